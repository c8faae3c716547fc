"""The encoder disk: a stationary ring of binary-labelled sectors around the scanner axis.

The disk is fixed to the robot (`base_link`), centred on the head's axis, face up, and
seen at the bottom of every camera frame as the head turns above it. Its single track
carries a de Bruijn sequence B(2, 5): every run of 5 consecutive sectors is unique, so
any visible run of 5 sectors fixes the heading absolutely (docs/architecture.md).

`disk_artwork` lays the disk out for printing at 1:1 with alignment marks; it is written
as SVG, PDF or PNG (`scanmap encoder-disk`).
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

import numpy as np

from .errors import CalibrationError

SHAFT_HOLE = 0.008  # m: radius of the hole in the disk for the head's shaft


def de_bruijn(order: int = 5) -> str:
    """The lexicographically least binary de Bruijn sequence of the given order, as '0'/'1'.

    Every binary word of length `order` appears exactly once as a cyclic window.
    Built by concatenating the Lyndon words whose length divides `order` (FKM algorithm).
    """
    if order < 1:
        raise ValueError("order must be >= 1")
    word = [0] * (order + 1)
    out: list[int] = []

    def extend(t: int, p: int) -> None:
        if t > order:
            if order % p == 0:
                out.extend(word[1:p + 1])
            return
        word[t] = word[t - p]
        extend(t + 1, p)
        for bit in range(word[t - p] + 1, 2):
            word[t] = bit
            extend(t + 1, t)

    extend(1, 1)
    return "".join(map(str, out))


def window_is_unique(code: str, window: int) -> bool:
    """True if every cyclic run of `window` sectors of `code` occurs once."""
    doubled = code + code[: window - 1]
    runs = {doubled[i:i + window] for i in range(len(code))}
    return len(runs) == len(code)


@dataclass(frozen=True)
class EncoderDisk:
    """Geometry and code of the disk, in `base_link`.

    height: z of the disk's printed face above the floor (m).
    inner_radius, outer_radius: the code ring (m).
    code: one '0'/'1' per sector, counter-clockwise from `zero_offset`; '1' is printed white.
    zero_offset: `base_link` angle (rad) where sector 0 starts; heading 0 is defined there.
    """

    height: float
    inner_radius: float
    outer_radius: float
    code: str
    zero_offset: float = 0.0

    def __post_init__(self) -> None:
        if not (0.0 < self.inner_radius < self.outer_radius):
            raise CalibrationError(
                f"encoder: expected 0 < inner_radius < outer_radius, got "
                f"{self.inner_radius}, {self.outer_radius}")
        if len(self.code) < 2 or set(self.code) - {"0", "1"}:
            raise CalibrationError(f"encoder.code: expected a string of '0'/'1', got {self.code!r}")

    @property
    def sectors(self) -> int:
        """Number of sectors on the ring."""
        return len(self.code)

    @property
    def sector_angle(self) -> float:
        """Angular width of one sector (rad)."""
        return 2.0 * np.pi / self.sectors

    def bits(self) -> np.ndarray:
        """The code as an int8 array, sector 0 first."""
        return np.frombuffer(self.code.encode(), dtype=np.uint8).astype(np.int8) - ord("0")

    def value_at(self, angle: np.ndarray) -> np.ndarray:
        """Printed value (0 or 1) of the ring at `base_link` angles (rad)."""
        index = np.floor((np.asarray(angle) - self.zero_offset) / self.sector_angle)
        return self.bits()[index.astype(np.int64) % self.sectors]

    def ray_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance along rays in `base_link` (directions (N, 3), origins (3,) common to
        all or (N, 3)) to the disk, inf where they miss it: the flat ring between the
        shaft's hole and `outer_radius` at `height`, exact, seen from above by the camera
        and from below by the laser."""
        origins = np.broadcast_to(origins, directions.shape)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (self.height - origins[:, 2]) / directions[:, 2]
        x = origins[:, 0] + t * directions[:, 0]
        y = origins[:, 1] + t * directions[:, 1]
        radius2 = x * x + y * y
        hit = (t > 0.0) & (radius2 <= self.outer_radius ** 2) & (radius2 >= SHAFT_HOLE ** 2)
        return np.where(hit, t, np.inf)


# ---------------------------------------------------------------------------------
# Printable artwork: one list of shapes in millimetres (page x right, y down), written
# as SVG, PDF (vector, written here) or PNG (rasterised with OpenCV). Seen from above,
# the print's +x (forward) points right and +y (left) up, so sectors run counter-clockwise.

PAGE_MARGIN = 12.0  # mm around the disk's marks
ARC_STEP = math.radians(0.25)  # polygon step along the arcs: 0.5 um from a true arc at 50 mm
COLOURS = {"black": (0.0, 0.0, 0.0), "white": (1.0, 1.0, 1.0), "red": (0.85, 0.0, 0.0)}


@dataclass(frozen=True)
class Polygon:
    """A filled polygon (mm)."""

    points: tuple[tuple[float, float], ...]
    fill: str


@dataclass(frozen=True)
class Stroke:
    """A polyline (mm), `width` mm wide; closed for circles."""

    points: tuple[tuple[float, float], ...]
    width: float
    colour: str
    closed: bool = False


@dataclass(frozen=True)
class Label:
    """Text with its baseline starting at `at` (mm), `size` mm high."""

    at: tuple[float, float]
    text: str
    size: float
    colour: str = "black"


@dataclass(frozen=True)
class Artwork:
    """The page (mm), the disk's centre on it (mm) and the shapes, drawn in order."""

    width: float
    height: float
    centre: tuple[float, float]
    shapes: tuple[Polygon | Stroke | Label, ...]


def disk_artwork(disk: EncoderDisk, outer_radius: float | None = None) -> Artwork:
    """The printable disk at 1:1: code ring, cut circles, centre cross, zero and axis marks,
    a 50 mm scale bar and a caption.

    outer_radius (m) scales the ring (the inner radius keeps its ratio); default: the
    disk's own. Sector k spans [k, k+1) * sector angle from the print's +x axis (the red
    zero mark), so `value_at` of the printed disk is the code with zero_offset 0; the
    offset of the mounted disk is calibrated.
    """
    outer = disk.outer_radius if outer_radius is None else float(outer_radius)
    if not (math.isfinite(outer) and 0.005 <= outer <= 0.5):
        raise CalibrationError(f"encoder disk radius: expected 0.005..0.5 m, got {outer_radius}")
    r1 = 1000.0 * outer
    r0 = r1 * disk.inner_radius / disk.outer_radius
    reach = r1 + 12.0
    width = max(2.0 * (reach + PAGE_MARGIN) + 40.0, 150.0)  # room for the labels
    height = 2.0 * (reach + PAGE_MARGIN) + 28.0
    c = (width / 2.0 - 20.0, PAGE_MARGIN + reach)

    def at(radius: float, angle: float) -> tuple[float, float]:
        return (c[0] + radius * math.cos(angle), c[1] - radius * math.sin(angle))

    def arc(radius: float, a0: float, a1: float) -> list[tuple[float, float]]:
        n = max(2, math.ceil(abs(a1 - a0) / ARC_STEP) + 1)
        return [at(radius, a0 + (a1 - a0) * i / (n - 1)) for i in range(n)]

    step = 2.0 * math.pi / disk.sectors
    shapes: list[Polygon | Stroke | Label] = []
    for k, bit in enumerate(disk.code):
        if bit == "0":
            a0, a1 = k * step, (k + 1) * step
            shapes.append(Polygon(tuple(arc(r1, a0, a1) + arc(r0, a1, a0)), "black"))
    for radius in (r0, r1):
        shapes.append(Stroke(tuple(arc(radius, 0.0, 2.0 * math.pi)[:-1]), 0.2, "black", True))
    shapes.append(Stroke((at(3.0, math.pi), at(3.0, 0.0)), 0.2, "black"))
    shapes.append(Stroke((at(3.0, -math.pi / 2), at(3.0, math.pi / 2)), 0.2, "black"))
    for quarter, name in enumerate(("+x forward, sector 0", "+y left", "", "")):
        angle = quarter * math.pi / 2
        colour = "red" if quarter == 0 else "black"
        shapes.append(Stroke((at(r1 + 2.0, angle), at(r1 + 10.0, angle)), 0.4, colour))
        if name:
            x, y = at(r1 + 2.0, angle)
            shapes.append(Label((x + 1.0, y - 2.0) if quarter == 0 else (x + 2.0, y - 4.0),
                                name, 2.5, colour))
    top = PAGE_MARGIN + 2.0 * reach + 6.0
    shapes.append(Polygon(((PAGE_MARGIN, top), (PAGE_MARGIN + 50.0, top),
                           (PAGE_MARGIN + 50.0, top + 2.0), (PAGE_MARGIN, top + 2.0)), "black"))
    shapes.append(Label((PAGE_MARGIN, top + 7.0),
                        "50 mm: print at 100 % and check with a ruler", 3.0))
    shapes.append(Label((PAGE_MARGIN, top + 12.0),
                        f"ring {2 * r0:.1f}-{2 * r1:.1f} mm diameter, {disk.sectors} sectors", 2.5))
    shapes.append(Label((PAGE_MARGIN, top + 16.0),
                        "counter-clockwise seen from above, 1 = white", 2.5))
    shapes.append(Label((PAGE_MARGIN, top + 20.0), f"code {disk.code}", 2.5))
    return Artwork(width=width, height=height, centre=c, shapes=tuple(shapes))


def artwork_svg(art: Artwork) -> str:
    """The artwork as an SVG document at 1:1 (mm)."""
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{art.width:.3f}mm" '
           f'height="{art.height:.3f}mm" viewBox="0 0 {art.width:.3f} {art.height:.3f}">',
           f'<rect width="{art.width:.3f}" height="{art.height:.3f}" fill="white"/>']
    for shape in art.shapes:
        if isinstance(shape, Polygon):
            pts = " ".join(f"{x:.4f},{y:.4f}" for x, y in shape.points)
            out.append(f'<polygon points="{pts}" fill="{shape.fill}"/>')
        elif isinstance(shape, Stroke):
            pts = " ".join(f"{x:.4f},{y:.4f}" for x, y in shape.points)
            tag = "polygon" if shape.closed else "polyline"
            out.append(f'<{tag} points="{pts}" fill="none" stroke="{shape.colour}" '
                       f'stroke-width="{shape.width}"/>')
        else:
            text = shape.text.replace("&", "&amp;").replace("<", "&lt;")
            out.append(f'<text x="{shape.at[0]:.3f}" y="{shape.at[1]:.3f}" '
                       f'font-family="Helvetica, Arial, sans-serif" '
                       f'font-size="{shape.size}" fill="{shape.colour}">{text}</text>')
    out.append("</svg>")
    return "\n".join(out) + "\n"


def artwork_pdf(art: Artwork) -> bytes:
    """The artwork as a one-page vector PDF at 1:1 (A4 when it fits)."""
    pt = 72.0 / 25.4
    page_w, page_h = max(210.0, art.width), max(297.0, art.height)
    dx, dy = (page_w - art.width) / 2.0, (page_h - art.height) / 2.0

    def xy(p: tuple[float, float]) -> str:
        return f"{(p[0] + dx) * pt:.3f} {(page_h - p[1] - dy) * pt:.3f}"

    ops = []
    for shape in art.shapes:
        if isinstance(shape, Label):
            rgb = " ".join(f"{v:g}" for v in COLOURS[shape.colour])
            text = shape.text.replace("\\", "\\\\").replace("(", "\\(").replace(")", "\\)")
            ops.append(f"{rgb} rg BT /F1 {shape.size * pt:.3f} Tf {xy(shape.at)} Td "
                       f"({text}) Tj ET")
            continue
        path = [f"{xy(shape.points[0])} m"] + [f"{xy(p)} l" for p in shape.points[1:]]
        if isinstance(shape, Polygon):
            rgb = " ".join(f"{v:g}" for v in COLOURS[shape.fill])
            ops.append(f"{rgb} rg " + " ".join(path) + " h f")
        else:
            rgb = " ".join(f"{v:g}" for v in COLOURS[shape.colour])
            close = " h" if shape.closed else ""
            ops.append(f"{rgb} RG {shape.width * pt:.3f} w " + " ".join(path) + close + " S")
    content = "\n".join(ops).encode("ascii")
    objects = [
        b"<< /Type /Catalog /Pages 2 0 R >>",
        b"<< /Type /Pages /Kids [3 0 R] /Count 1 >>",
        (f"<< /Type /Page /Parent 2 0 R /MediaBox [0 0 {page_w * pt:.3f} {page_h * pt:.3f}] "
         "/Resources << /Font << /F1 5 0 R >> >> /Contents 4 0 R >>").encode("ascii"),
        b"<< /Length %d >>\nstream\n" % len(content) + content + b"\nendstream",
        b"<< /Type /Font /Subtype /Type1 /BaseFont /Helvetica >>",
    ]
    pdf = bytearray(b"%PDF-1.4\n")
    offsets = []
    for number, body in enumerate(objects, start=1):
        offsets.append(len(pdf))
        pdf += b"%d 0 obj\n" % number + body + b"\nendobj\n"
    xref = len(pdf)
    pdf += b"xref\n0 %d\n0000000000 65535 f \n" % (len(objects) + 1)
    for offset in offsets:
        pdf += b"%010d 00000 n \n" % offset
    pdf += b"trailer\n<< /Size %d /Root 1 0 R >>\nstartxref\n%d\n%%%%EOF\n" % (
        len(objects) + 1, xref)
    return bytes(pdf)


def artwork_png(art: Artwork, dpi: float = 600.0) -> bytes:
    """The artwork rasterised at `dpi` (antialiased), as PNG bytes with the dpi recorded."""
    import cv2

    if not 50.0 <= dpi <= 2400.0:
        raise CalibrationError(f"encoder disk dpi: expected 50..2400, got {dpi}")
    shift = 4
    scale = dpi / 25.4 * (1 << shift)
    size = (round(art.height * dpi / 25.4), round(art.width * dpi / 25.4))
    image = np.full((*size, 3), 255, np.uint8)

    def px(points: tuple[tuple[float, float], ...]) -> np.ndarray:
        return np.round(np.array(points) * scale - (1 << shift) / 2).astype(np.int32)

    def bgr(name: str) -> tuple[int, int, int]:
        r, g, b = COLOURS[name]
        return round(255 * b), round(255 * g), round(255 * r)

    for shape in art.shapes:
        if isinstance(shape, Polygon):
            cv2.fillPoly(image, [px(shape.points)], bgr(shape.fill), cv2.LINE_AA, shift)
        elif isinstance(shape, Stroke):
            thickness = max(1, round(shape.width * dpi / 25.4))
            cv2.polylines(image, [px(shape.points)], shape.closed, bgr(shape.colour),
                          thickness, cv2.LINE_AA, shift)
        else:
            height_px = shape.size * dpi / 25.4
            origin = (round(shape.at[0] * dpi / 25.4), round(shape.at[1] * dpi / 25.4))
            cv2.putText(image, shape.text, origin, cv2.FONT_HERSHEY_SIMPLEX, height_px / 22.0,
                        bgr(shape.colour), max(1, round(height_px / 12)), cv2.LINE_AA)
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise CalibrationError("encoder disk: PNG encoding failed")
    return _with_dpi(data.tobytes(), dpi)


def _with_dpi(png: bytes, dpi: float) -> bytes:
    """Insert a pHYs chunk (pixels per metre) after the PNG's IHDR, so it prints to scale."""
    per_metre = round(dpi / 0.0254)
    body = b"pHYs" + struct.pack(">IIB", per_metre, per_metre, 1)
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    end_of_ihdr = 8 + 8 + 13 + 4
    return png[:end_of_ihdr] + chunk + png[end_of_ihdr:]
