"""Reprocess a fleet of recordings on a Dask cluster, with the results of the serial jobs.

`run_fleet(client, "process" | "map", inputs, out)` writes one folder per input under
`out`, named as the input folder:

* process: chunks of `chunk_scans` scans of one recording run as separate tasks (each
  assembles its scans exactly as `process_recording` does and writes scan_NNNN.npz/.ply),
  then one task merges their summaries in scan order into summary.json.
* map: one task per input runs `map_to_folder` (registration and fusion are sequential
  within a recording; recordings run in parallel).

Tasks read and write the file system directly, so inputs and `out` must be visible to
every worker under the same paths (one machine, or a shared file system). A task writes
into `out/.staging/NAME/`, which becomes `out/NAME/` by one rename once its manifest.json
(every file with its size and sha256) is written: a folder under `out` is complete or
absent. Every task can run twice (a worker killed mid-task has its tasks re-run) and
writes the same bytes. A re-run skips an input whose folder matches its manifest (same
job, input and options; every file's size and sha256) and redoes any other. An input that
fails (a corrupt recording) fails alone with its error; the run ends with a summary of
done, resumed and failed inputs, also written as `out/fleet_summary.json`.

Dask and distributed are the optional extra `cluster`; they are imported only here and in
the `fleet` command.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scanmap.datasets.recordings import ScanSource
from scanmap.mapping.config import MapperConfig
from scanmap.pipelines.offline import map_to_folder, offline_config
from scanmap_driver.errors import RecordingError, ScanmapError
from scanmap_driver.files import read_json, write_json
from scanmap_driver.processing import recording_scans, save_processed_scan
from scanmap_driver.recording import Recording
from scanmap_driver.scanner_model import ScannerModel

if TYPE_CHECKING:
    from distributed import Client, Future

JOBS = ("process", "map")
MANIFEST = "manifest.json"
MANIFEST_FORMAT = "scanmap.fleet_manifest/1"
SUMMARY = "fleet_summary.json"
SUMMARY_FORMAT = "scanmap.fleet_summary/1"
STAGING = ".staging"
NANNY_ENVIRON = "distributed.nanny.pre-spawn-environ"


def distributed_module() -> Any:
    """The `distributed` package, or a ScanmapError saying how to install it."""
    try:
        import distributed
    except ImportError as exc:
        raise ScanmapError(f"the fleet needs dask and distributed ({exc}); install them "
                           "with: pip install 'scanmap[cluster]'") from None
    return distributed


@contextlib.contextmanager
def connect(cluster: str) -> Iterator[Client]:
    """A client for `local[:N]` (a LocalCluster of N one-thread worker processes; N
    defaults to the number of cores) or `tcp://HOST:PORT` (a running scheduler)."""
    distributed = distributed_module()
    if cluster.startswith("tcp://"):
        with distributed.Client(cluster) as client:
            yield client
        return
    name, _, workers = cluster.partition(":")
    if name != "local" or (workers and not workers.isdigit()) or workers == "0":
        raise ScanmapError(f"--cluster {cluster!r}: expected local, local:N (N >= 1) or "
                           "tcp://HOST:PORT")
    import dask.config

    # distributed sets MALLOC_TRIM_THRESHOLD_ for its workers, which fixes glibc's malloc
    # thresholds: frame-sized arrays then cost nearly twice the CPU. Keep glibc's own.
    with dask.config.set({NANNY_ENVIRON + ".MALLOC_TRIM_THRESHOLD_": None}), \
            distributed.LocalCluster(n_workers=int(workers) if workers else None,
                                     threads_per_worker=1, processes=True) as local, \
            distributed.Client(local) as client:
        yield client


def fleet_inputs(inputs: str | Path) -> list[Path]:
    """The inputs: every sub-folder (not hidden) of a folder, in name order, or the paths
    listed one a line in a text file (relative to the file; blank and # lines skipped)."""
    inputs = Path(inputs)
    if inputs.is_dir():
        found = sorted(p for p in inputs.iterdir() if p.is_dir() and not p.name.startswith("."))
    elif inputs.is_file():
        lines = (line.strip() for line in inputs.read_text().splitlines())
        found = [inputs.parent / line for line in lines if line and not line.startswith("#")]
    else:
        raise ScanmapError(f"{inputs}: neither a folder of recordings nor a list of them")
    if not found:
        raise ScanmapError(f"{inputs}: no recordings in it")
    names = [p.name for p in found]
    doubled = sorted({n for n in names if names.count(n) > 1})
    if doubled:
        raise ScanmapError(f"{inputs}: output folder names used twice: {doubled}")
    return found


@dataclass(frozen=True)
class FleetJob:
    """One input's work. options: `scanner` (model file or None), `ply` (process),
    `config` (mapper TOML or None, map), `chunk_scans` (process); kept in the manifest."""

    kind: str
    source: Path
    out: Path
    options: dict = field(default_factory=dict)

    @property
    def staging(self) -> Path:
        """Where the tasks write before the folder is published."""
        return self.out.parent / STAGING / self.out.name

    def model(self) -> ScannerModel | None:
        """The scanner model file of the options, loaded; None: the input's own."""
        scanner = self.options.get("scanner")
        return ScannerModel.load(scanner) if scanner else None


@dataclass(frozen=True)
class Survey:
    """Why an input's folder must be (re)made (None: it is complete and verified) and,
    for `process`, the scan indices of each chunk task."""

    redo: str | None
    chunks: tuple[tuple[int, ...], ...] = ()


def file_record(path: Path) -> dict:
    """Size and sha256 of a file, as the manifest holds them."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return {"bytes": path.stat().st_size, "sha256": digest.hexdigest()}


def verify(job: FleetJob) -> str | None:
    """Why `job.out` is not a complete output of `job` (None: it is)."""
    path = job.out / MANIFEST
    if not path.is_file():
        return "no output yet"
    try:
        manifest = read_json(path, ScanmapError)
    except ScanmapError as exc:
        return str(exc)
    expected = _manifest_head(job)
    if {k: manifest.get(k) for k in expected} != expected:
        return f"{path}: made by another job, input or options"
    for name, record in manifest.get("files", {}).items():
        file = job.out / name
        if not file.is_file():
            return f"{file}: missing"
        if file_record(file) != record:
            return f"{file}: size or sha256 differs from {MANIFEST}"
    return None


def survey(job: FleetJob) -> Survey:
    """Task: is the input done; if not, open it (a corrupt one fails here) and plan it."""
    redo = verify(job)
    if redo is None:
        return Survey(None)
    if job.kind == "map":
        ScanSource.open(job.source, job.model())
        return Survey(redo)
    indices = [record.index for record in Recording.open(job.source).scans]
    if not indices:
        raise RecordingError(f"{job.source}: the recording has no scans")
    size = int(job.options.get("chunk_scans", 1))
    return Survey(redo, tuple(tuple(indices[i:i + size]) for i in range(0, len(indices), size)))


def process_chunk(job: FleetJob, indices: tuple[int, ...]) -> list[dict]:
    """Task: assemble and write these scans of the recording, as `process_recording`
    does; returns their summary entries in order."""
    recording = Recording.open(job.source)
    chunk = replace(recording, scans=tuple(recording.scan(i) for i in indices))
    ply = job.options.get("ply", True)
    return [save_processed_scan(scan, summary, error, job.staging, ply)
            for scan, summary, error in recording_scans(chunk, job.model())]


def finish_process(job: FleetJob, *chunks: list[dict]) -> dict:
    """Task: merge the chunks' summaries in order into summary.json and publish."""
    if verify(job) is None:  # a re-run after this task had published
        shutil.rmtree(job.staging, ignore_errors=True)
        return read_json(job.out / MANIFEST, ScanmapError)
    entries = [entry for chunk in chunks for entry in chunk]
    write_json(job.staging / "summary.json", {"recording": str(job.source), "scans": entries})
    files = [entry["file"] for entry in entries]
    if job.options.get("ply", True):
        files += [name.replace(".npz", ".ply") for name in files]
    return _publish(job, [*files, "summary.json"])


def map_input(job: FleetJob) -> dict:
    """Task: `map_to_folder` of one input (one assembly thread: a worker is one core),
    then publish."""
    shutil.rmtree(job.staging, ignore_errors=True)
    config = job.options.get("config")
    config = offline_config(MapperConfig.load(config) if config else None)
    report = map_to_folder(job.source, job.staging, model=job.model(), workers=1,
                           config=config)
    return _publish(job, list(report["files"].values()))


def _manifest_head(job: FleetJob) -> dict:
    return {"format": MANIFEST_FORMAT, "job": job.kind, "input": str(job.source),
            "options": job.options}


def _publish(job: FleetJob, files: list[str]) -> dict:
    """Write the manifest of `files`, drop anything else in staging, rename into place."""
    manifest = _manifest_head(job) | {"files": {name: file_record(job.staging / name)
                                                for name in files}}
    keep = {*files, MANIFEST}
    for path in job.staging.iterdir():
        if path.is_dir() and path.name not in keep:
            shutil.rmtree(path)
        elif path.name not in keep:
            path.unlink()
    write_json(job.staging / MANIFEST, manifest)
    if job.out.exists():
        old = job.staging.with_name(job.staging.name + ".old")
        shutil.rmtree(old, ignore_errors=True)
        job.out.rename(old)
        shutil.rmtree(old)
    job.staging.rename(job.out)
    return manifest


Progress = Callable[[dict, dict[str, int]], None]


def run_fleet(client: Client, kind: str, inputs: list[Path], out: str | Path, *,
              options: dict | None = None, progress: Progress | None = None) -> dict:
    """Run `kind` ("process" or "map") on every input on the cluster of `client`; returns
    the summary (also written to out/fleet_summary.json).

    progress(outcome, counts): called as each input ends, with its outcome (name, input,
    status done|resumed|failed, reason) and the counts so far.
    """
    if kind not in JOBS:
        raise ScanmapError(f"fleet job {kind!r}: expected one of {JOBS}")
    distributed = distributed_module()
    out = Path(out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    options = json.loads(json.dumps(options or {}, default=str))  # as the manifest holds them
    jobs = {src.name: FleetJob(kind, Path(src).resolve(), out / src.name, options)
            for src in inputs}
    owner: dict[Future, tuple[str, str]] = {}  # future -> (input name, stage)
    for name, job in jobs.items():
        owner[client.submit(survey, job, pure=False)] = (name, "survey")
    outcomes: dict[str, dict] = {}
    redo: dict[str, str] = {}
    counts = {"done": 0, "resumed": 0, "failed": 0, "tasks": len(owner)}
    pending = distributed.as_completed(list(owner))
    for future in pending:
        name, stage = owner.pop(future)
        job = jobs[name]
        outcome = None
        if future.status == "error":
            outcome = _outcome(job, "failed", _reason(future.exception()))
        elif future.status != "finished":
            outcome = _outcome(job, "failed", f"task {future.status}")
        elif stage == "survey":
            plan: Survey = future.result()
            if plan.redo is None:
                outcome = _outcome(job, "resumed", "complete and verified")
            else:
                redo[name] = plan.redo
                final = _submit_work(client, job, plan)
                counts["tasks"] += len(plan.chunks) + 1
                owner[final] = (name, "work")
                pending.add(final)
        else:
            outcome = _outcome(job, "done", f"made ({redo[name]})")
        future.release()
        if outcome:
            outcomes[name] = outcome
            counts[outcome["status"]] += 1
            if progress:
                progress(outcome, counts)
    summary = {"format": SUMMARY_FORMAT, "job": kind, "out": str(out),
               "options": options, "dashboard": _dashboard(client),
               **{status: [n for n in jobs if outcomes[n]["status"] == status]
                  for status in ("done", "resumed")},
               "failed": {n: outcomes[n]["reason"] for n in jobs
                          if outcomes[n]["status"] == "failed"},
               "inputs": [outcomes[n] for n in jobs]}
    write_json(out / SUMMARY, summary)
    with contextlib.suppress(OSError):  # left only when not empty
        (out / STAGING).rmdir()
    return summary


def _submit_work(client: Client, job: FleetJob, plan: Survey) -> Future:
    """The tasks that make one input's folder; returns the last one."""
    if job.kind == "map":
        return client.submit(map_input, job, pure=False)
    chunks = [client.submit(process_chunk, job, chunk, pure=False) for chunk in plan.chunks]
    return client.submit(finish_process, job, *chunks, pure=False)


def _outcome(job: FleetJob, status: str, reason: str) -> dict:
    return {"name": job.out.name, "input": str(job.source), "status": status,
            "reason": reason, "output": str(job.out) if status != "failed" else None}


def _reason(exc: BaseException | None) -> str:
    return f"{type(exc).__name__}: {exc}"


def _dashboard(client: Client) -> str | None:
    return getattr(client, "dashboard_link", None)
