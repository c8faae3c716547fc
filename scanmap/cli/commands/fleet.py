"""`scanmap fleet process|map INPUTS --out DIR --cluster local[:N] | tcp://HOST:8786`:
many recordings on a Dask cluster (see `scanmap.pipelines.fleet`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from tqdm import tqdm

from scanmap.pipelines.fleet import JOBS, SUMMARY, connect, fleet_inputs, run_fleet


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `fleet`."""
    parser = subparsers.add_parser(
        "fleet", help="process or map many recordings on a Dask cluster",
        description="Run `scanmap process` or `scanmap map` on every recording of INPUTS "
                    "(a folder of recordings, or a text file listing them one a line) on a "
                    "Dask cluster, one output folder per recording under DIR with its "
                    "manifest.json. A re-run skips the folders that are complete and "
                    "verified. Needs the optional extra `cluster` (dask, distributed); "
                    "the inputs and DIR must be visible to every worker.")
    parser.add_argument("job", choices=JOBS, help="what to run on each recording")
    parser.add_argument("inputs", type=Path, metavar="INPUTS",
                        help="folder of recordings, or text file listing them")
    parser.add_argument("--out", required=True, type=Path, metavar="DIR")
    parser.add_argument("--cluster", default="local", metavar="SPEC",
                        help="local[:N] (N worker processes of one thread; default: one "
                             "per core) or tcp://HOST:8786 (a running scheduler)")
    parser.add_argument("--scanner", type=Path, default=None, metavar="FILE",
                        help="scanner model to use instead of each recording's own")
    parser.add_argument("--no-ply", action="store_true", help="process: skip the .ply files")
    parser.add_argument("--chunk-scans", type=int, default=1, metavar="N",
                        help="process: scans per task (default 1)")
    parser.add_argument("--config", type=Path, default=None, metavar="FILE",
                        help="map: mapper configuration (TOML)")
    parser.set_defaults(func=_fleet)


def _fleet(args: argparse.Namespace) -> int:
    inputs = fleet_inputs(args.inputs)
    options = {"scanner": args.scanner and str(args.scanner.resolve())}
    if args.job == "process":
        options |= {"ply": not args.no_ply, "chunk_scans": max(1, args.chunk_scans)}
    else:
        options["config"] = args.config and str(args.config.resolve())
    with connect(args.cluster) as client:
        if client.dashboard_link:
            print(f"Dask dashboard: {client.dashboard_link}")
        with tqdm(total=len(inputs), unit="recording", desc=args.job,
                  dynamic_ncols=True) as bar:

            def progress(outcome: dict, counts: dict[str, int]) -> None:
                bar.set_postfix(counts, refresh=False)
                bar.update()
                if outcome["status"] == "failed":
                    bar.write(f"{outcome['name']}: failed: {outcome['reason']}")

            summary = run_fleet(client, args.job, inputs, args.out, options=options,
                                progress=progress)
    print(f"done {len(summary['done'])}, resumed {len(summary['resumed'])}, "
          f"failed {len(summary['failed'])}; summary in {args.out / SUMMARY}")
    return 1 if summary["failed"] else 0
