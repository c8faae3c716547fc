"""Durable files: a writer killed with SIGKILL at a random moment leaves the old file or the
new one, never a torn one; a recorder killed mid-scan keeps every frame written before.

Truth: the writer's own generations (each file's content is a function of its generation
number, checked in full) and the source recording's JPEG bytes.
"""

from __future__ import annotations

import itertools
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from scanmap_driver.errors import ScanmapError
from scanmap_driver.files import load_npz, read_json, remove_orphans, save_npz, write_json
from scanmap_driver.recording import Recording, read_avi_frames

KILLS = 8
NPZ_SIZE = 400_000
JSON_SIZE = 100_000

WRITER = """
import sys
from pathlib import Path
from tests.test_durable_writes import write_generation
generation = 1
while True:
    write_generation(sys.argv[1], Path(sys.argv[2]), generation)
    print(generation, flush=True)
    generation += 1
"""


def write_generation(kind: str, path: Path, generation: int) -> None:
    if kind == "npz":
        save_npz(path, generation=np.array(generation),
                 values=np.arange(NPZ_SIZE, dtype=np.int64) * generation)
    else:
        write_json(path, {"generation": generation, "values": [generation] * JSON_SIZE})


def read_generation(kind: str, path: Path) -> int:
    """The file's generation, after checking every value against it."""
    if kind == "npz":
        arrays = load_npz(path, ScanmapError, required=("generation", "values"))
        generation = int(arrays["generation"])
        assert np.array_equal(arrays["values"], np.arange(NPZ_SIZE) * generation)
    else:
        data = read_json(path, ScanmapError)
        generation = data["generation"]
        assert data["values"] == [generation] * JSON_SIZE
    return generation


def spawn(code: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", code, *args], stdout=subprocess.PIPE,
                            text=True, env=os.environ | {"PYTHONPATH": str(Path.cwd())})


def kill(child: subprocess.Popen) -> None:
    child.send_signal(signal.SIGKILL)
    child.wait()
    child.stdout.close()


@pytest.mark.parametrize("kind", ["npz", "json"])
def test_a_killed_writer_leaves_the_old_file_or_the_new_one(kind, tmp_path):
    rng = random.Random(kind)
    path = tmp_path / f"data.{kind}"
    write_generation(kind, path, 0)
    mid_write = 0
    for _ in range(KILLS):
        child = spawn(WRITER, kind, str(path))
        done = int(child.stdout.readline())  # the first write is finished
        time.sleep(rng.uniform(0.0, 0.3))
        kill(child)
        found = read_generation(kind, path)
        assert found >= done  # a finished write is never lost
        # the writer's first write swept what the one killed before had left
        leftovers = [p for p in tmp_path.iterdir() if p != path]
        assert len(leftovers) <= 1
        mid_write += bool(leftovers)
    assert mid_write > 0  # some kills landed inside a write: the hazard was exercised
    once = subprocess.run([sys.executable, "-c", WRITE_ONCE, kind, str(path)],
                          env=os.environ | {"PYTHONPATH": str(Path.cwd())}, check=True)
    assert once.returncode == 0
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no orphan left
    assert read_generation(kind, path) == -1


WRITE_ONCE = """
import sys
from pathlib import Path
from tests.test_durable_writes import write_generation
write_generation(sys.argv[1], Path(sys.argv[2]), -1)
"""


RECORDER = """
import sys, time
from scanmap_driver.recording import Recording, RecordingWriter, read_avi_frames
source = Recording.open(sys.argv[1])
record = source.scans[0]
jpegs = list(read_avi_frames(record.video))
writer = RecordingWriter(sys.argv[2], source.model, "kill test")
with writer.scan(0.0) as scan:
    for jpeg, t in zip(jpegs, record.frame_times):
        scan.add_jpeg(jpeg, float(t))
with writer.scan(100.0) as scan:
    scan.log_motor(100.0, "run", duty=0.72)
    for i, (jpeg, t) in enumerate(zip(jpegs, record.frame_times)):
        scan.add_jpeg(jpeg, 100.0 + float(t))
        print(i + 1, flush=True)
        time.sleep(0.02)
"""


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_recording_killed_mid_scan_keeps_every_frame_written(seed, office_recording,
                                                               tmp_path, capsys):
    source = Recording.open(office_recording).scans[0]
    jpegs = list(read_avi_frames(source.video))
    written_before_kill = random.Random(seed).randrange(1, len(jpegs) - 5)
    out = tmp_path / "rec"
    child = spawn(RECORDER, str(office_recording), str(out))
    while int(child.stdout.readline()) < written_before_kill:
        pass
    kill(child)

    recording = Recording.open(out)
    assert [r.index for r in recording.scans] == [0, 1]
    assert recording.scans[0].complete and not recording.scans[0].recovered
    cut = recording.scans[1]
    assert cut.recovered and not cut.complete
    assert written_before_kill <= len(cut.frame_times) < len(jpegs)
    assert np.allclose(cut.frame_times, 100.0 + source.frame_times[:len(cut.frame_times)])
    assert cut.motor_log == ({"t": 100.0, "command": "run", "duty": 0.72},)
    frames = list(recording.frames(1))
    assert len(frames) == len(cut.frame_times)
    saved = list(itertools.islice(read_avi_frames(cut.video), len(frames)))
    assert saved == jpegs[:len(frames)]  # byte for byte as the camera sent them

    from scanmap.cli import main  # here: the writer subprocesses import this module

    processed = tmp_path / "scans"
    assert main(["process", str(out), "--out", str(processed), "--no-ply"]) == 0
    printed = capsys.readouterr().out
    assert f"recovered {len(frames)} frames" in printed
    summary = json.loads((processed / "summary.json").read_text())
    assert summary["scans"][1]["frames"] == len(frames) and not summary["scans"][1]["complete"]


def test_only_the_temporary_files_of_dead_writers_are_removed(tmp_path):
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        names = {"live": f".map.npz.{live.pid}.ab_1.tmp.npz",
                 "dead": f".map.npz.{dead.pid}.cd_2.tmp.npz",
                 "user's": ".notes.txt", "plain": "map.npz"}
        for name in names.values():
            (tmp_path / name).write_bytes(b"x")
        removed = remove_orphans(tmp_path)
        assert [p.name for p in removed] == [names["dead"]]
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
            n for k, n in names.items() if k != "dead")
    finally:
        live.kill()
        live.wait()
