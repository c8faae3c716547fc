"""The DC motor that turns the head: slow start, speed ripple, coasting, and one scan's motion.

The paper drives the head with a cheap DC motor and reads the heading from the image, so
headings are not evenly spaced in time. `DcMotor` is a first-order motor: a duty cycle
above the stiction dead band sets a target speed that ripples with the shaft angle (gear
and commutator) and with a slowly wandering load; the speed follows with a time
constant, and braking stops it faster than coasting. `scan_motion` runs the paper's
reciprocating scan on it: start, one revolution plus a small overlap (the capture), brake,
and drive back to the start heading, where it stops close to, not exactly at, the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

STEP = 1e-3  # s: integration step and the resolution of the heading profile
GEAR_PHASES = (0.7, 2.1)  # rad: where the ripple peaks, fixed by the gear train


@dataclass(frozen=True)
class MotorModelConfig:
    """A small geared DC motor with the head on its shaft.

    full_speed: head speed (rad/s) at duty 1 and nominal load.
    dead_band: duty below which stiction holds the head still.
    time_constant: speed response to a duty change (s); the slow start.
    brake_time_constant: speed decay with the H-bridge braking (s).
    ripple: relative speed ripple once per revolution and at `ripple_order` per revolution.
    load_sigma: relative speed wander of the load (s^-1/2 random walk, mean-reverting).
    scan_duty: duty for the scanning revolution (about 2 s per revolution).
    return_duty: duty (negative: reverse) to bring the head back.
    """

    full_speed: float = 2.0 * math.pi * 0.8
    dead_band: float = 0.08
    time_constant: float = 0.18
    brake_time_constant: float = 0.04
    ripple: tuple[float, float] = (0.05, 0.02)
    ripple_order: int = 12
    load_sigma: float = 0.04
    load_time_constant: float = 0.5
    scan_duty: float = 0.72
    return_duty: float = -0.95


# Phase ends (`until` of `_integrate`).
RUN_STEPS, HEADING_ABOVE, STOPPED, HEADING_BELOW = 0, 1, 2, 3


@njit(cache=True, nogil=True)
def _integrate(state, duty, brake, until, value, noise, p):
    """Advance state = [heading, speed, load] step by step until `until` holds.

    p = [full_speed, dead_band, time_constant, brake_time_constant, ripple1, ripple2,
    ripple_order, load_decay, load_kick, phase1, phase2]. One `noise` sample per step;
    stops after len(noise) steps at the latest. Returns the headings after each step.
    """
    heading, speed, load = state[0], state[1], state[2]
    out = np.empty(noise.shape[0])
    n = 0
    alpha_run = 1.0 - np.exp(-STEP / p[2])
    alpha_brake = 1.0 - np.exp(-STEP / p[3])
    magnitude = min(abs(duty), 1.0)
    for i in range(noise.shape[0]):
        if until == HEADING_ABOVE and heading >= value:
            break
        if until == STOPPED and speed == 0.0:
            break
        if until == HEADING_BELOW and heading <= value - speed * p[3]:
            break
        load = load * p[7] + p[8] * noise[i]
        target = 0.0
        if magnitude > p[1]:
            ripple = p[4] * np.sin(heading + p[9]) + p[5] * np.sin(p[6] * heading + p[10])
            nominal = p[0] * (magnitude - p[1]) / (1.0 - p[1])
            target = nominal * (1.0 + ripple + load) * (1.0 if duty > 0.0 else -1.0)
        if target == 0.0 and abs(speed) < 1e-3:
            speed = 0.0
        else:
            alpha = alpha_brake if (brake and duty == 0.0) else alpha_run
            speed += (target - speed) * alpha
        heading += speed * STEP
        out[n] = heading
        n += 1
    state[0], state[1], state[2] = heading, speed, load
    return out[:n]


class DcMotor:
    """State (heading, speed, load) of the motor; `advance` integrates it under a duty.

    The same model serves the offline simulator and a simulated motor controller that
    receives duty commands in real time.
    """

    def __init__(self, params: MotorModelConfig, rng: np.random.Generator,
                 heading: float = 0.0) -> None:
        self.params = params
        self.rng = rng
        self.state = np.array([float(heading), 0.0, 0.0])
        decay = math.exp(-STEP / params.load_time_constant)
        self._p = np.array([params.full_speed, params.dead_band, params.time_constant,
                            params.brake_time_constant, params.ripple[0], params.ripple[1],
                            params.ripple_order, decay,
                            params.load_sigma * math.sqrt(1.0 - decay * decay),
                            *GEAR_PHASES])

    @property
    def heading(self) -> float:
        """Head angle (rad, unwrapped)."""
        return float(self.state[0])

    @property
    def speed(self) -> float:
        """Head speed (rad/s)."""
        return float(self.state[1])

    def advance(self, duty: float, duration: float, brake: bool = False) -> np.ndarray:
        """Run `duration` s, rounded to whole STEPs (at least one), at a constant duty
        (brake: short the motor at duty 0). Returns the heading after each STEP.
        """
        steps = max(1, round(duration / STEP))
        return self.run(duty, brake, RUN_STEPS, 0.0, steps)

    def run(self, duty: float, brake: bool, until: int, value: float,
            max_steps: int) -> np.ndarray:
        """Run until a phase end (`HEADING_ABOVE` value, `STOPPED`, `HEADING_BELOW` value)."""
        noise = self.rng.standard_normal(max_steps)
        return _integrate(self.state, float(duty), bool(brake), until, float(value), noise,
                          self._p)


@dataclass(frozen=True)
class ScanMotion:
    """The head's motion during one scan, from the start command to the end of the return.

    times, headings: the profile sampled every STEP seconds from time 0 (motor start).
    capture_end: when the heading first covered a full turn plus the overlap.
    end_heading: where the head came to rest after returning.
    log: the commands sent to the motor, as the recording's motor log.
    """

    times: np.ndarray
    headings: np.ndarray
    capture_end: float
    end_heading: float
    log: tuple[dict, ...]

    def heading_at(self, t: np.ndarray | float) -> np.ndarray:
        """Heading (rad, unwrapped) at times t (s)."""
        return np.interp(t, self.times, self.headings)

    @property
    def duration(self) -> float:
        """Time (s) from the start command until the head is back at rest."""
        return float(self.times[-1])


def scan_motion(params: MotorModelConfig, rng: np.random.Generator, start_heading: float,
                overlap: float = math.radians(10.0), limit: float = 10.0) -> ScanMotion:
    """Simulate one reciprocating scan starting at rest at `start_heading`.

    Each phase stops after `limit` seconds at the latest (a stalled motor).
    """
    motor = DcMotor(params, rng, start_heading)
    max_steps = round(limit / STEP)
    parts = [np.array([motor.heading])]
    log = []

    def phase(command: str, duty: float, until: int, value: float = 0.0) -> None:
        log.append({"t": round((sum(len(p) for p in parts) - 1) * STEP, 6),
                    "command": command, "duty": duty})
        parts.append(motor.run(duty, duty == 0.0, until, value, max_steps))

    phase("run", params.scan_duty, HEADING_ABOVE, start_heading + 2.0 * math.pi + overlap)
    capture_end = (sum(len(p) for p in parts) - 1) * STEP
    phase("brake", 0.0, STOPPED)
    phase("run", params.return_duty, HEADING_BELOW, start_heading)
    phase("brake", 0.0, STOPPED)
    headings = np.concatenate(parts)
    times = np.arange(headings.shape[0]) * STEP
    log.append({"t": round(float(times[-1]), 6), "command": "stop", "duty": 0.0})
    return ScanMotion(times, headings, capture_end, motor.heading, tuple(log))
