"""The hazards benchmark measures a scene file it was not built on (`--scene`)."""

from __future__ import annotations

import json

import numpy as np

from benchmarks.bench_hazards import _thinned, main
from scanmap_driver.sim.ideal import ideal_scans
from scanmap_driver.sim.scene import builtin_scene


def test_a_scene_file_gets_the_drop_off_and_ramp_measures(tmp_path, capsys):
    """The built-in hazards scene turned by 30 deg and cut to its first three scans, saved
    as a file: drop-offs are found where seen and none is free, its ramps are measured."""
    data = builtin_scene("hazards").moved(0.013, 0.021, 0.52).to_dict()
    data["scan_poses"] = data["scan_poses"][:3]
    path = tmp_path / "turned.json"
    path.write_text(json.dumps(data))
    assert main(["--scene", str(path)]) == 0
    measures = json.loads(capsys.readouterr().out)[str(path)]
    hazards = measures["hazards"]
    assert hazards["drop_cells"] > 0 and hazards["drop_found"] > 0  # three scans see part
    assert hazards["drop_free_any_scan"] == 0
    assert 0.0 < hazards["ramp_f1"] <= 1.0
    assert "people" not in measures  # a scene without people has no ghost measures


def test_a_rendered_room_mapped_by_the_whole_pipeline_frees_no_drop_off(capsys):
    """`--rendered`: a random and a mixed room's webcam frames rendered (eight scans each)
    and mapped by `scanmap map`, registration included: their drop-offs are found and
    none is free more than a cell inside; the random room's edge lies near the truth
    (the mixed room's lies 4.9 cells off, beyond its holes' far sides: README), and
    walls are found."""
    assert main(["--rendered", "1", "--first", "4", "--quick"]) == 0
    measures = json.loads(capsys.readouterr().out)
    room, worst = measures["random_room(4)"], measures["worst"]
    assert room["scans"] == 8 and worst["rooms"] == 2
    assert worst["drop_free"] == 0 and worst["drop_recall"] > 0.8
    assert room["edge_error_cells"] <= 2.0 and room["edge_within_one"] > 0.9
    assert worst["obstacle_f1"] > 0.9 and room["ate_m"] < 0.02


def test_a_rendered_approach_room_is_mapped_by_the_whole_pipeline(capsys):
    """`--rendered-approach`: a loading dock across the path, driven at head-on, through
    rendered frames and `scanmap map` (all 15 scans: the rendered stripe shows the floor
    from about 1.6 m, the dock only in the last ones): found, none of it free, its edge
    near the truth."""
    assert main(["--rendered-approach", "1", "--first", "3"]) == 0
    measures = json.loads(capsys.readouterr().out)
    room, worst = measures["approach_room(3)"], measures["worst"]
    assert room["scans"] == 15 and worst["rooms"] == 1
    assert room["drop_free"] == 0 and room["drop_recall"] > 0.8
    assert room["edge_error_cells"] <= 1.5 and room["ate_m"] < 0.02


def test_a_scan_thinned_for_the_timing_keeps_whole_frames_evenly():
    """The timing's 20,000-point scan: whole frames kept (every point of a kept frame,
    none of another), spread over the turn, about the points asked for."""
    ideal = next(ideal_scans(builtin_scene("corridor"), scans=1))
    thin = _thinned(ideal, 20_000)
    frames = np.unique(ideal.scan.frame_index)
    kept = np.unique(thin.scan.frame_index)
    assert abs(len(thin.scan) - 20_000) < 2 * len(ideal.scan) / len(frames)  # two frames
    for frame in frames:
        count = int((thin.scan.frame_index == frame).sum())
        assert count in (0, int((ideal.scan.frame_index == frame).sum()))
    assert np.diff(np.flatnonzero(np.isin(frames, kept))).max() <= 2  # none skipped twice
    assert len(thin.true_points) == len(thin.scan)
    assert _thinned(ideal, 10**9).scan.points.shape == ideal.scan.points.shape


def test_the_rendered_people_run_reads_the_frames_rendered_with_the_people():
    """`rendered_steps` on the people corridor's first five scans: each step holds the
    scan assembled from its rendered frames (people included: fewer points reach the
    walls than in the empty corridor's), and `people_run` measures them."""
    from dataclasses import replace

    from benchmarks.bench_hazards import people_run, rendered_steps

    scene = builtin_scene("people")
    short = replace(scene, scan_poses=scene.scan_poses[:5])
    with_people = [len(step.ideal.scan) for step in rendered_steps(short)]
    empty = [len(step.ideal.scan) for step in rendered_steps(replace(short, people=()))]
    assert all(n > 10000 for n in with_people)
    assert sum(with_people) < sum(empty)
    rendered = people_run(5, scene=short, rendered=True)
    assert rendered["wall_cells_eroded"] == 0 and rendered["wall_recall_people"] > 0.95
