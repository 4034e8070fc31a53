"""The drive's own tuning functions inside the simulated loop: torque-command notch filters and friction
compensation as a torque feed-forward (issue 34 item 4), each from the parameters a profile maps to its roles.

What the manuals document: SD25 (section 9.4) and IS620P (H09-12..H09-23) each have four torque-command notches set
by a frequency, a width level and a depth level; DSX7E Pn120-122 and SDC PN137-140 add a torque offset and a torque
by direction (and SDC a damping term, % of rated torque at the rated speed). What they leave open is the
simulator's own and listed as a simulator extension (model.roles.sim_extensions): how a width and a depth level
shape the filter (here: width level w gives a -3 dB band of w * WIDTH_PER_LEVEL of the centre frequency; depth
level d passes d % at the centre, the Inovance convention), and when a compensation by direction switches (here: by
the sign of the speed reference, none within DIRECTION_DEADBAND_RPM of zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

WIDTH_PER_LEVEL = 0.1  # a width level's share of the centre frequency (the notch's -3 dB band)
MAX_SHARE_OF_RATE = 0.4  # a notch at or above this share of the control rate is inert (the loop cannot see it)
DIRECTION_DEADBAND_RPM = 1.0  # a compensation by direction acts beyond this speed reference


@dataclass(frozen=True)
class NotchSetting:
    """One notch: centre frequency (Hz), width level (the -3 dB band = level * WIDTH_PER_LEVEL * centre), depth
    level (% passed at the centre: 0 cuts it out, 100 leaves it)."""

    hz: float
    width_level: float
    depth_level: float

    def active(self, ts: float) -> bool:
        return 0 < self.hz < MAX_SHARE_OF_RATE / ts and self.width_level > 0 and self.depth_level < 100


class Notch:
    """A notch as a biquad (bilinear, prewarped to the centre): (s^2 + 2 d z w s + w^2) / (s^2 + 2 z w s + w^2)."""

    def __init__(self, setting: NotchSetting, ts: float) -> None:
        w0 = 2.0 / ts * math.tan(math.pi * setting.hz * ts)
        bandwidth = 2 * math.pi * setting.hz * setting.width_level * WIDTH_PER_LEVEL
        zeta = bandwidth / (2 * 2 * math.pi * setting.hz)
        depth = max(0.0, min(1.0, setting.depth_level / 100.0))
        k = 2.0 / ts
        a0 = k * k + 2 * zeta * w0 * k + w0 * w0
        self.b = ((k * k + 2 * depth * zeta * w0 * k + w0 * w0) / a0, (2 * w0 * w0 - 2 * k * k) / a0)
        self.b2 = (k * k - 2 * depth * zeta * w0 * k + w0 * w0) / a0
        self.a1 = (2 * w0 * w0 - 2 * k * k) / a0
        self.a2 = (k * k - 2 * zeta * w0 * k + w0 * w0) / a0
        self.z1 = self.z2 = 0.0

    def step(self, x: float) -> float:
        """One sample (transposed direct form II)."""
        y = self.b[0] * x + self.z1
        self.z1 = self.b[1] * x - self.a1 * y + self.z2
        self.z2 = self.b2 * x - self.a2 * y
        return y


@dataclass(frozen=True)
class FrictionFeedForward:
    """Torque added to the speed regulator's output (% of rated torque): an offset, a Coulomb term by the speed
    reference's direction and a damping term proportional to the reference (% at the rated speed)."""

    offset_pct: float = 0.0
    coulomb_fwd_pct: float = 0.0
    coulomb_rev_pct: float = 0.0
    viscous_fwd_pct: float = 0.0
    viscous_rev_pct: float = 0.0

    def torque_pct(self, reference_rpm: float, rated_rpm: float) -> float:
        if reference_rpm > DIRECTION_DEADBAND_RPM:
            return self.offset_pct + self.coulomb_fwd_pct + self.viscous_fwd_pct * reference_rpm / rated_rpm
        if reference_rpm < -DIRECTION_DEADBAND_RPM:
            return self.offset_pct - self.coulomb_rev_pct + self.viscous_rev_pct * reference_rpm / rated_rpm
        return self.offset_pct

    @property
    def any(self) -> bool:
        return any(
            (self.offset_pct, self.coulomb_fwd_pct, self.coulomb_rev_pct, self.viscous_fwd_pct, self.viscous_rev_pct)
        )


@dataclass(frozen=True)
class GainSwitch:
    """Gain switching (SD25 Po130, section 9.3.5, L7851-7869) on the conditions the simulator runs: 'gain1' and
    'gain2' (no switching), 'speed' (above speed_rpm: gain 2 at once; below it: gain 1 after delay_s). Gain 2 is the
    second speed-loop gain, integral time and position gain. Other conditions (DI, position error, pulse input)
    are not simulated: gain 1 (the simulated drive has no pulse input and no GAIN-SEL input)."""

    condition: str = "gain1"
    speed_rpm: float = 10.0
    delay_s: float = 0.1
    speed_gain_hz: float = 40.0
    speed_integral_ms: float = 20.0
    position_gain_per_s: float = 40.0

    @property
    def any(self) -> bool:
        return self.condition in ("gain2", "speed")


class GainSelector:
    """Which gain set acts now (1 or 2), stepped once a control period with the measured speed."""

    def __init__(self, switch: GainSwitch) -> None:
        self.switch = switch
        self.active = 2 if switch.condition == "gain2" else 1
        self._below_s = 0.0

    def step(self, speed_rpm: float, ts: float) -> int:
        s = self.switch
        if s.condition != "speed":
            return self.active
        if abs(speed_rpm) > s.speed_rpm:
            self.active, self._below_s = 2, 0.0
        elif self.active == 2:
            self._below_s += ts
            if self._below_s >= s.delay_s:
                self.active = 1
        return self.active
