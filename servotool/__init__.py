"""servotool: commission and tune AC servo drives over Modbus RTU."""

__version__ = "0.1.0"
