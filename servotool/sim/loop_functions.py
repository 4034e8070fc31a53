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

    @property
    def memory(self) -> list[float]:
        """The filter's state (what it remembers of past samples), to hand the running loop over."""
        return [self.z1, self.z2]

    def recall(self, memory: list[float]) -> None:
        self.z1, self.z2 = memory[0], memory[1]

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
class FrictionObserver:
    """Friction compensation from an estimate of the disturbance (SD25 Po183-187, section 9.6): the manual says it
    compensates changes of viscous friction and of a constant load (L8007), a higher gain 1/2 answers disturbances
    faster but may vibrate on a resonance (L8042), a higher coefficient compensates more and vibrates sooner, keep it
    at 95 % or less (L8036-8044), and it needs the inertia ratio right (L8020). How: the simulator's own (a
    listed extension): a first-order disturbance observer on the configured inertia, whose bandwidth is the gain's
    share of the acting speed-loop gain times OBSERVER_X, adds coefficient % of the estimate to the torque command;
    gain 2 acts with the second gain set."""

    enabled: bool = False
    coefficient_pct: float = 0.0
    gain_pct: float = 100.0
    gain_2_pct: float = 100.0

    @property
    def any(self) -> bool:
        return self.enabled and self.coefficient_pct > 0


OBSERVER_X = 1.0  # observer bandwidth at gain 100 %: this many times the acting speed-loop gain (unverified)


class DisturbanceObserver:
    """d = LPF(T) - J wc (w - LPF(w)): the torque not explained by J dw/dt, low-passed at wc, without a derivative."""

    def __init__(self) -> None:
        self.torque = 0.0  # LPF(T), N*m
        self.speed = 0.0  # LPF(w), rad/s
        self.estimate = 0.0  # N*m

    @property
    def memory(self) -> list[float]:
        return [self.torque, self.speed, self.estimate]

    def recall(self, memory: list[float]) -> None:
        self.torque, self.speed, self.estimate = memory

    def step(self, torque_nm: float, w: float, j: float, bandwidth_hz: float, ts: float) -> float:
        """One control period: the disturbance estimate (N*m) from the torque commanded and the measured speed."""
        wc = 2 * math.pi * max(bandwidth_hz, 0.1)
        k = wc * ts / (1.0 + wc * ts)
        self.torque += (torque_nm - self.torque) * k
        self.speed += (w - self.speed) * k
        self.estimate = self.torque - j * wc * (w - self.speed)
        return self.estimate


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

    @property
    def memory(self) -> list[float]:
        """Which set acts and how long the speed has been below the switching speed, to hand the loop over."""
        return [float(self.active), self._below_s]

    def recall(self, memory: list[float]) -> None:
        active, self._below_s = memory
        self.active = 2 if active == 2 else 1

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
