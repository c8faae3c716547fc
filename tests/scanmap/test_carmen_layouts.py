"""CARMEN beam layouts: each line type, PARAM inference and the beam-count convention on a
synthetic square room (points must land on its walls), bad input, and the sharpness of
the maps of the real logs with the inferred layout against a deliberately wrong step."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from benchmarks.carmen_logs import carmen_logs, carmen_path
from scanmap.cli import main
from scanmap.datasets.carmen import NEGATIVE, NONFINITE, TRUNCATED, BeamLayout, read_carmen
from scanmap.pipelines.carmen_map import occupied_cells_per_reading
from scanmap_driver.errors import RecordingError
from scanmap_driver.transforms import se2_to_pose, transform_points
from tests.conftest import real_data

HALF = 3.0  # the room: walls at x = +-3 m and y = +-3 m
POSES = np.array([[0.0, 0.0, 0.0], [1.0, -0.5, 0.7], [-1.2, 0.8, -2.5]])


def room_ranges(pose: np.ndarray, angles_deg: np.ndarray) -> np.ndarray:
    """Range from `pose` to the nearest wall of the room along each beam (robot frame)."""
    a = np.deg2rad(angles_deg) + pose[2]
    d = np.stack([np.cos(a), np.sin(a)], axis=1)
    best = np.full(len(a), np.inf)
    for axis in (0, 1):
        for wall in (HALF, -HALF):
            with np.errstate(divide="ignore"):
                t = (wall - pose[axis]) / d[:, axis]
            best = np.where((t > 0) & (t < best), t, best)
    return best


def wall_distance(log) -> np.ndarray:
    """Distance of every read point, at the log's poses, to the room's walls."""
    pts = np.vstack([transform_points(se2_to_pose(*log.poses[i]), log.scan_points(i))[:, :2]
                     for i in range(len(log))])
    return np.abs(np.abs(pts).max(axis=1) - HALF)


def numbers(values) -> str:
    return " ".join(f"{v:.6f}" for v in values)


def flaser(ranges, pose, t: float, tag: str = "FLASER") -> str:
    """An old-format laser line; its odometry equals its pose."""
    return f"{tag} {len(ranges)} {numbers([*ranges, *pose, *pose, t])} host {t}\n"


def header(start_deg: float, step_deg: float, n: int) -> str:
    """laser_type start_angle field_of_view angular_resolution max_range accuracy mode."""
    start, step = np.deg2rad(start_deg), np.deg2rad(step_deg)
    return f"0 {start:.9f} {step * (n - 1):.9f} {step:.9f} 81.9 0.01 0"


def robotlaser(ranges, start_deg, step_deg, laser_pose, robot_pose, t: float) -> str:
    rem = np.full(len(ranges), 7.0)
    return (f"ROBOTLASER1 {header(start_deg, step_deg, len(ranges))} {len(ranges)} "
            f"{numbers(ranges)} {len(rem)} {numbers(rem)} {numbers(laser_pose)} "
            f"{numbers(robot_pose)} 0 0 0.5 0.3 0 {t} host {t}\n")


def rawlaser(ranges, start_deg, step_deg, t: float) -> str:
    return (f"RAWLASER1 {header(start_deg, step_deg, len(ranges))} {len(ranges)} "
            f"{numbers(ranges)} 0 {t} host {t}\n")


def odom(pose, t: float) -> str:
    return f"ODOM {numbers(pose)} 0 0 0 {t} host {t}\n"


def write(tmp_path: Path, lines: list[str]) -> Path:
    path = tmp_path / "room.log"
    path.write_text("".join(lines))
    return path


def flaser_room(count: int, first_deg: float, step_deg: float) -> list[str]:
    angles = first_deg + step_deg * np.arange(count)
    return [flaser(room_ranges(p, angles), p, float(k)) for k, p in enumerate(POSES)]


@pytest.mark.parametrize("count, step_deg", [(180, 1.0), (181, 1.0), (360, 0.5), (361, 0.5)])
def test_beam_count_convention_puts_points_on_the_walls(tmp_path, count, step_deg):
    log = read_carmen(write(tmp_path, flaser_room(count, -90.0, step_deg)))
    assert "beam count" in log.layout.source and log.skipped == {}
    assert wall_distance(log).max() < 0.01


@pytest.mark.parametrize("params", [
    ["PARAM laser_front_laser_fov 90 nohost 0\n",
     "PARAM laser_front_laser_resolution 0.5 nohost 0\n"],
    ["PARAM robot_front_laser_fov 90 nohost 0\n",
     "PARAM laser_frontlaser_resolution 0.5 0.0 nohost 0\n"],  # fhw writes a second value
])
def test_param_lines_give_the_layout(tmp_path, params):
    """181 beams of 0.5 deg over 90 deg: the count alone would say 1 deg over 180 deg."""
    log = read_carmen(write(tmp_path, params + flaser_room(181, -45.0, 0.5)))
    assert "PARAM" in log.layout.source
    assert wall_distance(log).max() < 0.01


def test_param_contradicting_the_count_names_file_line_and_param(tmp_path):
    lines = ["PARAM laser_front_laser_resolution 1 nohost 0\n", *flaser_room(361, -90, 0.5)]
    with pytest.raises(RecordingError, match=r"room.log:2: FLASER: 361 beams of 1 deg.*line 1"):
        read_carmen(write(tmp_path, lines))


def test_rear_laser_params_do_not_apply_to_the_front(tmp_path):
    lines = ["PARAM laser_rear_laser_resolution 0.25 nohost 0\n", *flaser_room(361, -90, 0.5)]
    log = read_carmen(write(tmp_path, lines))
    assert wall_distance(log).max() < 0.01


def test_robotlaser_states_its_layout(tmp_path):
    """100 beams of 1.2 deg from -60 deg: no convention could guess it."""
    angles = -60.0 + 1.2 * np.arange(100)
    lines = [robotlaser(room_ranges(p, angles), -60.0, 1.2, p, p + 0.1, float(k))
             for k, p in enumerate(POSES)]
    log = read_carmen(write(tmp_path, lines))
    assert log.layout.source == "ROBOTLASER1 line 1"
    np.testing.assert_allclose(log.poses, POSES, atol=1e-6)
    np.testing.assert_allclose(log.odometry, POSES + 0.1, atol=1e-6)  # the robot pose
    assert wall_distance(log).max() < 0.01


def test_rawlaser_is_posed_by_the_odometry_and_counted_before_it(tmp_path):
    angles = -70.0 + 0.7 * np.arange(201)
    lines = [rawlaser(room_ranges(POSES[0], angles), -70.0, 0.7, 0.0)]  # no pose yet
    for k, p in enumerate(POSES):
        lines += [odom(p, k + 0.5), rawlaser(room_ranges(p, angles), -70.0, 0.7, k + 0.6)]
    path = write(tmp_path, lines)
    log = read_carmen(path, laser="raw1")
    assert len(log) == len(POSES)
    assert log.skipped == {"RAWLASER1 lines before any ODOM (no pose)": 1}
    np.testing.assert_allclose(log.poses, POSES, atol=1e-6)
    assert wall_distance(log).max() < 0.01
    with pytest.raises(RecordingError, match="4 RAWLASER1: choose that laser"):
        read_carmen(path)  # the front laser is not there


def test_other_lasers_are_counted_not_mixed(tmp_path):
    rear = [flaser(np.full(180, 2.0), p, 9.0, tag="RLASER") for p in POSES]
    log = read_carmen(write(tmp_path, flaser_room(180, -90, 1.0) + rear))
    assert len(log) == len(POSES) and wall_distance(log).max() < 0.01
    assert log.skipped == {"RLASER lines (not the front laser)": 3}
    assert len(read_carmen(tmp_path / "room.log", laser="rear")) == 3


@pytest.mark.parametrize("change, fragment", [
    (lambda lines: lines[:2] + [flaser(np.full(181, 2.0), POSES[0], 5.0)],
     r"room.log:3: 181 beams, the log's first scan \(line 1\) has 180"),
    (lambda lines: [robotlaser(np.full(180, 2.0), -90, 1.0, POSES[0], POSES[0], 0.0),
                    robotlaser(np.full(180, 2.0), -90, 0.5, POSES[0], POSES[0], 1.0)],
     r"room.log:2: beam layout 180 beams from -90.00 deg, step 0.500 deg"),
    (lambda lines: [lines[0], lines[1][:200] + "\n", lines[2]],
     r"room.log:2: FLASER needs 188 numbers, got \d+ \(the line is cut short\)"),
    (lambda lines: [flaser(np.full(200, 2.0), POSES[0], 0.0), lines[1]],
     r"room.log:1: FLASER: 200 beams: no layout is stated"),
    (lambda lines: [lines[0], flaser(np.full(180, 2.0), [0, np.nan, 0], 1.0)],
     r"room.log:2: a pose is not finite"),
    (lambda lines: [lines[0], odom([0.0, np.inf, 0.0], 0.5), lines[1]],
     r"room.log:2: ODOM: the pose is not finite"),
    (lambda lines: [lines[0].replace(lines[0].split()[2], "x", 1)],
     r"room.log:1: FLASER has a non-numeric field"),
])
def test_bad_input_names_file_and_line(tmp_path, change, fragment):
    with pytest.raises(RecordingError, match=fragment):
        read_carmen(write(tmp_path, change(flaser_room(180, -90.0, 1.0))))


def test_a_cut_last_line_is_skipped_and_counted(tmp_path):
    lines = flaser_room(180, -90.0, 1.0)
    log = read_carmen(write(tmp_path, lines[:2] + [lines[2][:300], "\n\n"]))
    assert len(log) == 2 and log.skipped == {TRUNCATED: 1}


def test_carmen_map_command_prints_layout_and_skips(tmp_path, capsys):
    lines = flaser_room(361, -90.0, 0.5)
    path = write(tmp_path, lines + [lines[0][:100]])
    assert main(["carmen-map", str(path), "--out", str(tmp_path / "map")]) == 0
    out = capsys.readouterr().out
    assert "beam layout: 361 beams from -90.00 deg, step 0.500 deg (beam count 361)" in out
    assert f"skipped: 1 {TRUNCATED}" in out and (tmp_path / "map" / "room.yaml").exists()


def test_nan_and_negative_readings_are_counted_and_dropped(tmp_path):
    angles = -90.0 + np.arange(180)
    ranges = room_ranges(POSES[0], angles)
    ranges[[3, 50]] = np.nan
    ranges[[7, 8, 9]] = -1.0
    log = read_carmen(write(tmp_path, [flaser(ranges, POSES[0], 0.0)]))
    assert log.skipped == {NONFINITE: 2, NEGATIVE: 3}
    no_return = np.sum(ranges == np.nanmax(ranges))  # the log's largest reading: "no return"
    assert len(log.scan_points(0)) == 180 - 5 - no_return and wall_distance(log).max() < 0.01
    assert log.max_range == pytest.approx(np.nanmax(ranges), abs=1e-6)


# The real logs: beam counts as their README states them.
REAL_COUNTS = {"intel": 180, "aces": 180, "acapulco": 181, "belgioioso": 361,
               "edmonton": 180, "fhw": 180, "freiburg-101": 360}


@pytest.mark.parametrize("name", carmen_logs() or sorted(REAL_COUNTS))
def test_real_log_is_sharper_with_its_layout_than_with_a_wrong_step(name):
    """Every 2nd of the first 500 scans of every log present (the shared seven and any
    other beside them): the inferred layout's map must take clearly fewer occupied cells
    per reading than the same scans with half (1 deg logs) or twice (0.5 deg logs) the
    step."""
    log = read_carmen(real_data(f"carmen/{carmen_path(name).name}")).subset(slice(0, 500, 2))
    layout = log.layout
    if name in REAL_COUNTS:
        assert layout.count == REAL_COUNTS[name]
        assert np.rad2deg(layout.first) == pytest.approx(-90.0)
    wrong_step = layout.step * (0.5 if np.rad2deg(layout.step) > 0.75 else 2.0)
    wrong = dataclasses.replace(log, layout=BeamLayout(layout.count, layout.first, wrong_step,
                                                       "deliberately wrong"))
    right_cells, wrong_cells = occupied_cells_per_reading(log), occupied_cells_per_reading(wrong)
    assert wrong_cells > 1.4 * right_cells, (right_cells, wrong_cells)
