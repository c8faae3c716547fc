"""Encoder disk code: de Bruijn property, sector lookup; the printable artwork (SVG, PNG,
PDF) read back independently, and decoded by the camera end to end; the CLI."""

from __future__ import annotations

import re
import struct
from xml.etree import ElementTree

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from scanmap.cli import main
from scanmap_driver.encoder import decode_heading
from scanmap_driver.encoder_disk import (
    EncoderDisk,
    artwork_pdf,
    artwork_png,
    artwork_svg,
    de_bruijn,
    disk_artwork,
    window_is_unique,
)
from scanmap_driver.errors import CalibrationError
from scanmap_driver.scanner_model import reference_scanner
from scanmap_driver.sim.synthetic_frames import disk_frame


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6])
def test_de_bruijn_contains_every_word_once(order):
    code = de_bruijn(order)
    assert len(code) == 2**order
    doubled = code + code[: order - 1]
    words = {doubled[i:i + order] for i in range(len(code))}
    assert words == {format(k, f"0{order}b") for k in range(2**order)}


def test_any_five_sectors_fix_the_position_but_four_do_not():
    code = de_bruijn(5)
    assert window_is_unique(code, 5)
    assert not window_is_unique(code, 4)


@given(st.floats(-20.0, 20.0), st.floats(-1.0, 1.0))
def test_value_at_follows_sectors(angle, offset):
    disk = EncoderDisk(height=0.9, inner_radius=0.03, outer_radius=0.05, code=de_bruijn(5),
                       zero_offset=offset)
    sector = int(np.floor((angle - offset) / disk.sector_angle)) % 32
    assert disk.value_at(np.array(angle)) == int(disk.code[sector])


def test_invalid_disks():
    with pytest.raises(CalibrationError, match="inner_radius"):
        EncoderDisk(height=0.9, inner_radius=0.05, outer_radius=0.03, code="0101")
    with pytest.raises(CalibrationError, match="code"):
        EncoderDisk(height=0.9, inner_radius=0.03, outer_radius=0.05, code="01x1")


# ---------------------------------------------------------------- printable artwork

DISK = EncoderDisk(height=0.927, inner_radius=0.035, outer_radius=0.05, code=de_bruijn(5))


def sector_of(dx: float, dy_up: float) -> int:
    """Sector index of a direction given with y pointing up (counter-clockwise angles)."""
    return int(np.floor(np.mod(np.arctan2(dy_up, dx), 2 * np.pi) / DISK.sector_angle))


def test_svg_is_to_scale_counter_clockwise_with_the_code():
    art = disk_artwork(DISK)
    root = ElementTree.fromstring(artwork_svg(art))
    assert root.get("width") == f"{art.width:.3f}mm"
    cx, cy = art.centre
    black = []
    for poly in root.iter("{http://www.w3.org/2000/svg}polygon"):
        pts = np.array([p.split(",") for p in poly.get("points").split()], float)
        radius = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy)
        if poly.get("fill") == "black" and len(pts) > 4:  # a sector, not the scale bar
            assert radius.min() == pytest.approx(35.0, abs=1e-3)
            assert radius.max() == pytest.approx(50.0, abs=1e-3)
            mid = pts.mean(axis=0)
            black.append(sector_of(mid[0] - cx, cy - mid[1]))
    assert sorted(black) == [k for k, bit in enumerate(DISK.code) if bit == "0"]


def test_png_samples_give_the_code_and_carry_the_dpi(tmp_path):
    dpi = 300.0
    data = artwork_png(disk_artwork(DISK, 0.06), dpi)
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR" and data[37:41] == b"pHYs"
    per_metre = struct.unpack(">II", data[41:49])
    assert per_metre == (round(dpi / 0.0254),) * 2
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    art = disk_artwork(DISK, 0.06)
    mid = 0.5 * (60.0 + 60.0 * 35.0 / 50.0)  # mm, middle of the scaled ring
    for k, bit in enumerate(DISK.code):
        angle = (k + 0.5) * DISK.sector_angle
        x = (art.centre[0] + mid * np.cos(angle)) * dpi / 25.4
        y = (art.centre[1] - mid * np.sin(angle)) * dpi / 25.4
        assert (image[round(y), round(x)] > 128) == (bit == "1")


def test_pdf_is_well_formed_vector_art_to_scale():
    pdf = artwork_pdf(disk_artwork(DISK))
    assert pdf.startswith(b"%PDF-1.4") and pdf.rstrip().endswith(b"%%EOF")
    xref = int(re.search(rb"startxref\n(\d+)", pdf).group(1))
    assert pdf[xref:xref + 4] == b"xref"
    offsets = [int(o) for o in re.findall(rb"(\d{10}) 00000 n", pdf)]
    for number, offset in enumerate(offsets, start=1):
        assert pdf[offset:].startswith(b"%d 0 obj" % number)
    media = [float(v) for v in re.search(rb"/MediaBox \[([^\]]+)\]", pdf).group(1).split()]
    assert media[2:] == pytest.approx([595.276, 841.89], abs=0.01)  # A4
    stream = re.search(rb"stream\n(.*)\nendstream", pdf, re.S).group(1).decode()
    pt = 72 / 25.4
    circles = []
    for stroke in re.findall(r"RG [\d.]+ w (.*?) h S", stream):
        pts = np.array(re.findall(r"([\d.]+) ([\d.]+) [ml]", stroke), float)
        if len(pts) > 100:
            circles.append(pts)
    assert len(circles) == 2
    centre = circles[0].mean(axis=0)
    radii = sorted(np.hypot(*(c - centre).T).mean() / pt for c in circles)
    assert radii == pytest.approx([35.0, 50.0], abs=0.01)
    black = []
    for fill in re.findall(r"0 0 0 rg (.*?) h f", stream):
        pts = np.array(re.findall(r"([\d.]+) ([\d.]+) [ml]", fill), float)
        if len(pts) > 4:  # a sector, not the scale bar
            mid = pts.mean(axis=0) - centre
            black.append(sector_of(mid[0], mid[1]))  # PDF y points up
    assert sorted(black) == [k for k, bit in enumerate(DISK.code) if bit == "0"]


def test_printed_disk_seen_by_the_camera_decodes_to_the_heading():
    """End to end: the PNG artwork as the disk's texture, rendered into frames, decoded."""
    dpi = 600.0
    art = disk_artwork(DISK)
    image = cv2.imdecode(np.frombuffer(artwork_png(art, dpi), np.uint8),
                         cv2.IMREAD_GRAYSCALE) / 255.0

    def texture(xy):
        col = np.round((art.centre[0] + 1000 * xy[:, 0]) * dpi / 25.4 - 0.5).astype(int)
        row = np.round((art.centre[1] - 1000 * xy[:, 1]) * dpi / 25.4 - 0.5).astype(int)
        return image[row, col]

    model = reference_scanner()
    rng = np.random.default_rng(0)
    for theta in (-2.0, 0.4, 2.9):
        frame = disk_frame(model, theta, rng, texture=texture)
        result = decode_heading(frame, model)
        assert result.ok
        assert abs(np.degrees(np.angle(np.exp(1j * (result.heading - theta))))) < 0.1


@pytest.mark.parametrize("suffix", [".svg", ".png", ".pdf"])
def test_cli_writes_each_format(tmp_path, suffix):
    out = tmp_path / f"disk{suffix}"
    assert main(["encoder-disk", "--out", str(out), "--radius", "0.045", "--dpi", "150"]) == 0
    head = out.read_bytes()[:8]
    assert head.startswith({".svg": b"<svg", ".png": b"\x89PNG", ".pdf": b"%PDF"}[suffix])


def test_cli_uses_a_scanner_file_and_refuses_bad_input(tmp_path, capsys):
    model = reference_scanner().with_changes(encoder=EncoderDisk(
        height=0.927, inner_radius=0.02, outer_radius=0.04, code="01" * 16))
    model.save(tmp_path / "scanner.json")
    out = tmp_path / "disk.svg"
    assert main(["encoder-disk", "--out", str(out), "--scanner",
                 str(tmp_path / "scanner.json")]) == 0
    assert "0101" * 8 in out.read_text()
    assert main(["encoder-disk", "--out", str(out), "--radius", "-1"]) == 1
    assert "radius" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["encoder-disk", "--out", str(tmp_path / "disk.jpg")])
    assert main(["encoder-disk", "--out", str(out), "--scanner",
                 str(tmp_path / "missing.json")]) == 1
