"""`scanmap encoder-disk --out disk.svg|png|pdf [--radius M]`: the printable encoder disk.

The disk of a scanner model (the reference scanner by default) at 1:1 with its alignment
marks: cut circles, centre cross, the red zero mark (sector 0 starts there; point it to
the robot's forward direction), axis ticks, and a 50 mm scale bar to check the print.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scanmap_driver import ScannerModel, reference_scanner
from scanmap_driver.encoder_disk import artwork_pdf, artwork_png, artwork_svg, disk_artwork
from scanmap_driver.files import atomic_path

FORMATS = (".svg", ".png", ".pdf")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `encoder-disk`."""
    parser = subparsers.add_parser(
        "encoder-disk", help="write the printable encoder disk (SVG, PNG or PDF)",
        description="Write the encoder disk to print at 1:1, with alignment marks. Print at "
                    "100 %% (no fit-to-page) and check the 50 mm scale bar with a ruler.")
    parser.add_argument("--out", required=True, type=_output, metavar="FILE",
                        help="output file: .svg, .png or .pdf")
    parser.add_argument("--radius", type=float, metavar="M",
                        help="outer radius of the code ring (m); the inner radius keeps "
                             "its ratio (default: the model's)")
    parser.add_argument("--scanner", type=Path, metavar="FILE",
                        help="scanner model whose disk to print (default: reference scanner)")
    parser.add_argument("--dpi", type=float, default=600.0,
                        help="resolution of a PNG (default 600)")
    parser.set_defaults(func=run)


def _output(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in FORMATS:
        raise argparse.ArgumentTypeError(
            f"{text}: expected a file ending in {', '.join(FORMATS)}")
    return path


def run(args: argparse.Namespace) -> int:
    """Write the disk; returns the exit code."""
    model = ScannerModel.load(args.scanner) if args.scanner else reference_scanner()
    art = disk_artwork(model.encoder, args.radius)
    suffix = args.out.suffix.lower()
    data = (artwork_svg(art).encode() if suffix == ".svg" else
            artwork_pdf(art) if suffix == ".pdf" else artwork_png(art, args.dpi))
    with atomic_path(args.out) as tmp:
        tmp.write_bytes(data)
    print(f"wrote {args.out} ({art.width:.0f} x {art.height:.0f} mm, print at 100 %)")
    return 0
