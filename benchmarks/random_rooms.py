"""Random hazard rooms: scenes the hazard rules were not built on (the families below).

The built-in `hazards` and `workshop` scenes are where the rules were shaped; a rule that
holds only there is tuned to them. Each room is drawn afresh from its seed.

`random_room(seed)`: a walled 10 m x 5 m room with eight hazards on alternate sides of a
weaving path (26 stop-and-scan poses 0.3 m apart, the heading following the path within 3
deg): two holes 0.3-0.6 m wide and 0.2-0.6 m deep, a step down of 6-20 cm, a pit 0.6-1.0
m across and 0.1-0.3 m deep, a platform 8-30 cm high, a low step of 1-4 cm (traversable),
a ramp of 4-11 deg (traversable) and one of 20-30 deg (not), each turned by up to 46 deg
(the ramps rise along x), their order along the room shuffled. A hole's other side is
0.8-1.3 times the first but never under `FloorConfig.max_hole` (0.3 m): a smaller hole,
while nothing in it or at its rim has been seen, is a patch the rules may take for a gap
between samples.

`ramp_room(seed)`: the random room of the same seed but for its ramps, which lie where only
the slope's estimate tells them apart: the gentle one 12-14.7 deg, the steep one 15.5-17.5
deg (`FloorConfig.max_slope` is 15 deg), each turned by up to 46 deg, rising across the
turn, so the laser's lines cross their cells anywhere.

`mixed_room(seed)` holds what those rooms lack, in a room 13.6 m long and 4-6 m wide:
three holes 0.3-0.7 m wide and 0.1-0.8 m deep, a hole 0.3-0.6 m wide whose inside returns
nothing (black-lined), black carpet 0.3-1.0 m on a side, a stairwell 2 m deep, a step down,
a pit, a ramp of 3-12 deg, a glass panel and a box, at alternate sides of a path whose
poses lie 0.3-0.6 m apart (the heading within 12 deg of the path), in ambient light
0.3-0.9. A black-lined hole returns nothing, as black carpet does: it is told apart only
by its size, so one a little wider than `max_hole` may be taken for carpet (the lit gaps
around it widen the patch the rules measure).

`step_room(seed)`: the step the robot can only just not take, in the 9 m x 5 m room: one
step down 5.5-9 cm deep (`RobotShape.step_height` is 5 cm), 0.9 m square and turned by up
to 46 deg, 1-1.6 m beside a path of 15 poses 0.5 m apart (within 0.2 m of the room's
axis, the heading within 6 deg). Where its face crosses the cells at a slant it leaves
levels at in-between heights, each within a step of the next, across up to three cells.

`terrain_room(seed)`: floors at other heights the robot may reach, in a room 5 m wide and
11.5-16 m long, along a path of poses 0.4 m apart (within 0.15 m of the room's axis, the
heading within 5 deg): on one side a dock 6-30 cm down running 2-3 m beside the path
(1-1.5 m from the axis out to the wall), then a stair of four steps down, each 12-19 cm
and 0.28 m deep, and farther on a ramp of 4-12 deg up to a landing 8-20 cm high; on the
other side a ramp of 4-12 deg down to a sunken floor 10-25 cm down. The landing and the
sunken floor are floor (reached by their ramps), the dock and the stair drop-offs. The
sunken floor's rim, where the floor above meets it, is a cliff from that side: a map
that marks its cells there DROP_OFF counts them false drop-offs against the truth
raster, which holds one class a cell and calls them floor.

`approach_room(seed)`: a hazard across the robot's path, driven at head-on (every other
family lies beside the path): a corridor 2.6-4 m wide whose floor, 4-5.5 m ahead, turns
by up to 35 deg to the path into (by the seed, in turn) a ramp of 4-14.5 deg down to a
floor 8-19 cm lower, a ramp as steep up to a landing 6-25 cm high (both wall to wall: the
lower floor is reached by its ramp), a step down of 5.5-19 cm (wall to wall), a loading
dock 0.3-1 m down, or four stairs down, each 12-19 cm and 0.25-0.32 m deep, to a floor
a riser lower (both with a 0.25 m ledge along each wall and the far one: the walls end
0.2 m down); the robot drives up to it, poses 0.25-0.4 m apart (within 0.1 m of the
axis, the heading within 0.06 rad), and stops 0.15-0.5 m from the edge, its footprint on
the floor. Seen from afar, the floor past the edge shows first through a few laser lines
running down the slope, its near edge seen from above or not at all.

`people_room(seed)`: people pass while walls and furniture stay, in a walled room 7-10 m
long and 2.8-4 m wide with three cabinets (0.4-0.9 m long, 0.4 m deep, 0.7 m high,
turned by up to 17 deg) against its long walls, their faces at any offset to the cells;
the robot creeps along the centre line over PEOPLE_SCANS scans while four people pass
in lanes between it and the cabinets: two walk the room's length in 6-20 scans, two
stand 5-20 scans and leave; each waits and ends behind the east wall, out of sight.
"""

from __future__ import annotations

import math

import numpy as np

from scanmap_driver.sim.scene import Scene

HAZARDS = ("hole", "hole", "step down", "pit", "platform", "low step", "ramp", "steep ramp")
POSES = 26
POSE_STEP = 0.3  # m along x between poses


RAMPS = {"ramp": (4.0, 11.0), "steep ramp": (20.0, 30.0)}  # deg, square to the room
NEAR_MAX_SLOPE = {"ramp": (12.0, 14.7), "steep ramp": (15.5, 17.5)}  # deg, turned


def _region(kind: str, x: float, y: float, rng: np.random.Generator,
            near_max_slope: bool = False) -> dict:
    """One hazard (a scene file's floor region) centred near (x, y); a ramp as in
    `ramp_room` with `near_max_slope`."""
    turned = rng.random() < 0.6 and "ramp" not in kind
    region = {"center": [round(x, 3), round(y, 3)], "name": kind, "color": [130, 130, 130],
              "yaw": round(float(rng.uniform(-0.8, 0.8)), 3) if turned else 0.0}
    if kind == "hole":
        side = rng.uniform(0.3, 0.6)  # the other side 0.8-1.3 times it, never under max_hole
        region |= {"size": [round(side, 3), round(max(side * rng.uniform(0.8, 1.3), 0.3), 3)],
                   "height": round(-rng.uniform(0.2, 0.6), 3)}
    elif kind == "pit":
        region |= {"size": [round(rng.uniform(0.6, 1.0), 3), round(rng.uniform(0.6, 1.0), 3)],
                   "height": round(-rng.uniform(0.1, 0.3), 3)}
    elif kind == "step down":
        region |= {"size": [0.9, 0.9], "height": round(-rng.uniform(0.06, 0.2), 3)}
    elif kind == "platform":
        region |= {"size": [0.7, 0.6], "height": round(rng.uniform(0.08, 0.3), 3)}
    elif kind == "low step":
        region |= {"size": [0.7, 0.7], "height": round(rng.uniform(0.01, 0.04), 3)}
    else:  # a ramp rising along its x from the floor at its low edge
        degrees = rng.uniform(*(NEAR_MAX_SLOPE if near_max_slope else RAMPS)[kind])
        gradient = math.tan(math.radians(degrees))
        region["size"] = [1.0, 0.9]
        if near_max_slope:  # turned, rising along its own x
            yaw = round(float(rng.uniform(-0.8, 0.8)), 3)
            region |= {"yaw": yaw, "height": round(0.5 * gradient + 5e-4, 4),
                       "gradient": [round(gradient * math.cos(yaw), 5),
                                    round(gradient * math.sin(yaw), 5)]}
        else:  # rounded up: never below 0
            region |= {"gradient": [round(gradient, 4), 0.0],
                       "height": round(0.5 * gradient + 2e-4, 4)}
    return region


MIXED = ("hole", "hole", "hole", "black-lined hole", "black carpet", "stairwell", "step down",
         "pit", "ramp", "glass", "box")
HAZARD_STEP = 1.1  # m along x between the mixed rooms' hazards
PEOPLE_SCANS = 45


def _mixed_region(kind: str, centre: list[float], rng: np.random.Generator) -> dict:
    """One of the mixed room's floor regions (a scene file's entry) at `centre`."""
    region = {"center": centre, "name": kind, "color": [130, 130, 130],
              "yaw": round(float(rng.uniform(-0.8, 0.8)), 3) if rng.random() < 0.5 else 0.0}
    side = round(float(rng.uniform(0.3, 0.7)), 3)
    if kind == "hole":
        region |= {"size": [side, round(max(side * rng.uniform(0.7, 1.4), 0.3), 3)],
                   "height": round(-rng.uniform(0.1, 0.8), 3)}
    elif kind == "black-lined hole":
        side = round(float(rng.uniform(0.3, 0.6)), 3)
        region |= {"size": [side, side], "height": round(-rng.uniform(0.1, 0.5), 3),
                   "reflectance": 0.0, "color": [20, 20, 20]}
    elif kind == "black carpet":
        region |= {"size": [round(float(rng.uniform(0.3, 1.0)), 3) for _ in range(2)],
                   "height": 0.0, "reflectance": 0.0, "color": [20, 20, 20]}
    elif kind == "stairwell":
        region |= {"size": [round(float(rng.uniform(0.6, 0.9)), 3) for _ in range(2)],
                   "height": -2.0}
    elif kind == "step down":
        region |= {"size": [0.9, 0.9], "height": round(-rng.uniform(0.06, 0.25), 3)}
    elif kind == "pit":
        region |= {"size": [round(float(rng.uniform(0.5, 1.0)), 3)] * 2,
                   "height": round(-rng.uniform(0.06, 0.3), 3)}
    else:  # a ramp rising along x
        gradient = math.tan(math.radians(rng.uniform(3.0, 12.0)))
        region |= {"size": [0.9, 0.8], "gradient": [round(gradient, 4), 0.0], "yaw": 0.0,
                   "height": round(0.45 * gradient + 2e-4, 4)}
    return region


def mixed_room(seed: int) -> Scene:
    """The mixed room of the module docstring drawn from `seed`."""
    rng = np.random.default_rng(seed)
    kinds = list(MIXED)
    rng.shuffle(kinds)
    length, width = HAZARD_STEP * len(kinds) + 1.5, rng.uniform(4.0, 6.0)
    regions, objects = [], []
    for k, kind in enumerate(kinds):
        side = 1 if k % 2 else -1
        centre = [round(0.6 + HAZARD_STEP * k + rng.uniform(-0.15, 0.15), 3),
                  round(side * rng.uniform(1.2, 0.5 * width - 0.8), 3)]
        if kind in ("glass", "box"):
            glass = kind == "glass"
            objects.append({"type": "box", "center": centre + [0.5 if glass else 0.2],
                            "size": [0.6, 0.02, 1.0] if glass else [0.5, 0.4, 0.4],
                            "yaw": round(float(rng.uniform(-0.8, 0.8)), 3), "name": kind,
                            "color": [220, 230, 230] if glass else [90, 110, 160]}
                           | ({"surface": "glass"} if glass else {}))
        else:
            regions.append(_mixed_region(kind, centre, rng))
    step, amplitude = rng.uniform(0.3, 0.6), rng.uniform(0.0, 0.2)
    phase = rng.uniform(0.0, 2 * math.pi)
    poses = [[round(x, 3), round(amplitude * math.sin(x / 1.3 + phase), 4),
              round(float(rng.uniform(-0.2, 0.2)), 4)]
             for x in step * np.arange(int((length - 2.5) / step) + 1)]
    return _room(f"mixed room {seed}", f"mixed_room({seed})", length, width,
                 float(rng.uniform(0.3, 0.9)), objects, regions, poses)


def _room(name: str, source: str, length: float, width: float, ambient: float,
          objects: list[dict], regions: list[dict], poses: list[list[float]],
          people: list[dict] | None = None) -> Scene:
    """A walled room from x = -1.05 to `length` - 1.05, `width` wide about y = 0, holding
    `objects`, `regions` and `people`, scanned from `poses`."""
    wall = {"type": "box", "color": [200, 196, 190]}
    east, half = length - 1.05, 0.5 * width
    walls = [wall | {"center": [round(0.5 * (east - 1.05), 3), round(y, 3), 0.65],
                     "size": [round(east + 1.15, 3), 0.1, 1.7]} for y in (-half, half)] \
        + [wall | {"center": [x, 0.0, 0.65], "size": [0.1, round(width - 0.1, 3), 1.7]}
           for x in (-1.05, round(east, 3))]
    return Scene.from_dict({
        "format": "scanmap.scene/1", "name": name,
        "description": f"{source}: {__doc__.splitlines()[0]}",
        "floor": {"color": [150, 140, 125]}, "ambient": ambient, "texture": 0.25,
        "objects": walls + objects, "floor_regions": regions, "people": people or [],
        "scan_poses": poses},
        source=source)


def random_room(seed: int) -> Scene:
    """The room of the module docstring drawn from `seed` (the same seed, the same room)."""
    return _hazard_room(seed, False)


def ramp_room(seed: int) -> Scene:
    """`random_room(seed)` with its ramps near max_slope, turned (the module docstring)."""
    return _hazard_room(seed, True)


def _hazard_room(seed: int, near_max_slope: bool) -> Scene:
    """`random_room` or, with `near_max_slope`, `ramp_room`."""
    rng = np.random.default_rng(seed)
    kinds = list(HAZARDS)
    rng.shuffle(kinds)
    regions = [_region(kind, 1.0 + k + rng.uniform(-0.2, 0.2),
                       (1.4 if k % 2 else -1.4) + rng.uniform(-0.1, 0.1), rng, near_max_slope)
               for k, kind in enumerate(kinds)]
    phase, amplitude = rng.uniform(0.0, 2 * math.pi), rng.uniform(0.1, 0.35)
    poses = []
    for k in range(POSES):
        x = POSE_STEP * k
        slope = amplitude / 1.3 * math.cos(x / 1.3 + phase)
        poses.append([round(x, 3), round(amplitude * math.sin(x / 1.3 + phase), 4),
                      round(math.atan(slope) + rng.uniform(-0.05, 0.05), 4)])
    family = "ramp" if near_max_slope else "random"
    return _room(f"{family} room {seed}", f"{family}_room({seed})", 10.1, 5.1, 0.8, [], regions,
                 poses)


def step_room(seed: int) -> Scene:
    """The room with one turned step down of the module docstring drawn from `seed`."""
    rng = np.random.default_rng(seed)
    depth, yaw = rng.uniform(0.055, 0.09), rng.uniform(-0.8, 0.8)
    centre = [round(float(rng.uniform(2.0, 5.0)), 3),
              round((1 if seed % 2 else -1) * float(rng.uniform(1.0, 1.6)), 3)]
    region = {"center": centre, "size": [0.9, 0.9], "yaw": round(float(yaw), 3),
              "height": round(-float(depth), 4), "name": "step down", "color": [130, 130, 130]}
    poses = [[0.5 * k, round(float(rng.uniform(-0.2, 0.2)), 3),
              round(float(rng.uniform(-0.1, 0.1)), 3)] for k in range(15)]
    return _room(f"step room {seed}", f"step_room({seed})", 9.1, 5.1, 0.8, [], [region],
                 poses)


def _ramp_to_floor(rng: np.random.Generator, x: float, side: int, down: bool,
                   rise: tuple[float, float], across: tuple[float, float], width: float,
                   floor: float, names: tuple[str, str]) -> tuple[list[dict], float]:
    """A ramp of 4-12 deg along x from the floor at `x`, `down` or up, to a square floor
    `floor` m on a side beyond it, `rise` m (drawn) below or above the floor, its centre
    `across` m (drawn) from the room's axis on `side`; the two regions and the ramp's
    length."""
    gradient = math.tan(math.radians(rng.uniform(4.0, 12.0)))
    sign = 1.0 if down else -1.0
    length = round(float(rng.uniform(*rise)) / gradient, 2)
    middle = round(0.5 * gradient * length, 4) + 3e-4  # rounded away from the floor
    y = round(side * float(rng.uniform(*across)), 3)
    return [{"center": [round(x + 0.5 * length, 3), y], "size": [length, width],
             "height": -sign * middle, "gradient": [-sign * round(gradient, 5), 0.0],
             "name": names[0]},
            {"center": [round(x + length + 0.5 * floor, 3), y], "size": [floor, floor],
             "height": round(-sign * 2.0 * middle, 4), "name": names[1]}], length


def terrain_room(seed: int) -> Scene:
    """The room with floors at other heights of the module docstring drawn from `seed`."""
    rng = np.random.default_rng(seed)
    side = 1 if seed % 2 else -1
    edge, start = float(rng.uniform(1.0, 1.5)), round(float(rng.uniform(0.0, 1.0)), 2)
    end = round(start + float(rng.uniform(2.0, 3.0)), 2)
    regions = [{"center": [round(0.5 * (start + end), 3), round(side * 0.5 * (edge + 2.5), 3)],
                "size": [round(end - start, 3), round(2.5 - edge, 3)], "name": "dock",
                "height": round(-float(rng.uniform(0.06, 0.3)), 3)}]
    stair_x, stair_y = end + round(float(rng.uniform(0.3, 0.6)), 2), side * rng.uniform(1.2, 1.5)
    riser = float(rng.uniform(0.12, 0.19))
    regions += [{"center": [round(stair_x + 0.14 + 0.28 * k, 3), round(stair_y, 3)],
                 "size": [0.28, 0.9], "height": round(-riser * (k + 1), 3),
                 "name": f"stair {k + 1}"} for k in range(4)]
    down_x = round(float(rng.uniform(4.5, 5.0)), 2)
    down, length = _ramp_to_floor(rng, down_x, -side, True, (0.1, 0.25), (1.3, 1.6), 0.9,
                                  1.2, ("ramp down", "sunken floor"))
    up_x = round(down_x + length + 2.2, 2)
    up, length = _ramp_to_floor(rng, up_x, side, False, (0.08, 0.2), (1.2, 1.5), 0.8, 0.8,
                                ("ramp up", "landing"))
    regions += down + up
    room_length = up_x + length + 2.5
    poses = [[round(0.4 * k, 3), round(float(rng.uniform(-0.15, 0.15)), 3),
              round(float(rng.uniform(-0.08, 0.08)), 3)]
             for k in range(int((room_length - 1.5) / 0.4))]
    return _room(f"terrain room {seed}", f"terrain_room({seed})", round(room_length + 1.05, 2),
                 5.1, 0.8, [], [region | {"color": [130, 130, 130]} for region in regions],
                 poses)


def people_room(seed: int) -> Scene:
    """The room with people of the module docstring drawn from `seed`."""
    rng = np.random.default_rng(seed)
    length, width = rng.uniform(7.0, 10.0), rng.uniform(2.8, 4.0)
    half, east = 0.5 * width, length - 1.05
    cabinets = [{"type": "box", "color": [120, 100, 80], "name": "cabinet",
                 "center": [round(float(rng.uniform(0.5, east - 1.5)), 3),
                            round((1 if k % 2 else -1) * (half - 0.25), 3), 0.35],
                 "size": [round(float(rng.uniform(0.4, 0.9)), 3), 0.4, 0.7],
                 "yaw": round(float(rng.uniform(-0.3, 0.3)), 3)} for k in range(3)]
    hidden = east + 0.6  # behind the east wall
    people = []
    for k in range(4):
        side = 1 if rng.random() < 0.5 else -1  # clear of the robot and the cabinets
        lane = round(side * float(rng.uniform(0.5, half - 0.7)), 3)
        if k % 2 == 0:  # walks the room's length
            start = int(rng.integers(1, PEOPLE_SCANS - 8))
            end = min(start + int(rng.integers(6, 21)), PEOPLE_SCANS - 1)
            ends = [east - 0.5, -0.5] if rng.random() < 0.5 else [-0.5, east - 0.5]
            track = [[start - 1, hidden, lane], [start, ends[0], lane], [end, ends[1], lane],
                     [end + 1, hidden, lane]]
        else:  # stands, then leaves
            start = int(rng.integers(1, PEOPLE_SCANS // 2))
            end = start + int(rng.integers(5, 21))
            x = round(float(rng.uniform(0.5, east - 1.5)), 3)
            track = [[start - 1, hidden, lane], [start, x, lane], [end, x, lane],
                     [end + 1, hidden, lane]]
        people.append({"radius": round(float(rng.uniform(0.15, 0.22)), 3),
                       "height": round(float(rng.uniform(1.5, 1.85)), 3),
                       "color": [90, 70, 160], "name": f"person {k}",
                       "track": [[t, round(float(x), 3), y] for t, x, y in track]})
    step = (length - 3.0) / PEOPLE_SCANS
    poses = [[round(step * k, 3), 0.0, 0.0] for k in range(PEOPLE_SCANS)]
    return _room(f"people room {seed}", f"people_room({seed})", length, width, 0.8, cabinets,
                 [], poses, people)


APPROACH = ("ramp down", "ramp up", "step down", "dock", "stairs down")
LEDGE = 0.25  # m of floor between a dock's or a stair's side and the wall


def _strip(near: float, angle: float, start: float, end: float | None, half: float,
           wall: float) -> list[list[float]]:
    """The floor from `start` to `end` m past the line through (near, 0) turned by `angle`
    (its normal (cos, sin) pointing away from the robot), or with `end` None up to the
    wall x = `wall`, between y = -half and half: a convex polygon, counter-clockwise."""
    def x_at(depth: float, y: float) -> float:
        return round(near + (depth - math.sin(angle) * y) / math.cos(angle), 4)
    if end is None:
        return [[x_at(start, -half), -half], [wall, -half], [wall, half], [x_at(start, half), half]]
    return [[x_at(start, -half), -half], [x_at(end, -half), -half], [x_at(end, half), half],
            [x_at(start, half), half]]


def approach_room(seed: int) -> Scene:
    """The room with a hazard across the path of the module docstring drawn from `seed`."""
    rng = np.random.default_rng(seed)
    kind = APPROACH[seed % len(APPROACH)]
    width, near = rng.uniform(2.6, 4.0), rng.uniform(4.0, 5.5)
    angle = rng.uniform(-0.61, 0.61)  # the edge's normal against the path
    inner = 0.5 * width - 0.05  # the walls' inner faces
    ledges = kind in ("dock", "stairs down")
    half = round(inner - (LEDGE if ledges else 0.0), 4)
    far = round(near + (3.0 + math.sin(abs(angle)) * inner) / math.cos(angle), 3)  # the
    # east wall's inner face: 3 m past the edge where it lies farthest off
    end_x = far - (LEDGE if ledges else 0.0)

    def region(name: str, start: float, end: float | None, height: float,
               gradient: float = 0.0) -> dict:
        slope = [round(gradient * math.cos(angle), 6), round(gradient * math.sin(angle), 6)]
        return {"polygon": _strip(near, angle, start, end, half, end_x), "height": height,
                "gradient": slope, "name": name, "color": [130, 130, 130]}

    if kind in ("ramp down", "ramp up"):
        sign = -1.0 if kind == "ramp down" else 1.0
        gradient = math.tan(math.radians(rng.uniform(4.0, 14.5)))
        drop = rng.uniform(0.08, 0.19) if kind == "ramp down" else rng.uniform(0.06, 0.25)
        length = drop / gradient
        middle = sign * (0.5 * drop + 3e-4)  # rounded away from the floor
        regions = [region(kind, 0.0, length, round(middle, 5), sign * gradient),
                   region("lower floor" if sign < 0 else "landing", length, None,
                          round(2.0 * middle, 5))]
    elif kind == "stairs down":
        riser, tread = rng.uniform(0.12, 0.19), rng.uniform(0.25, 0.32)
        regions = [region(f"stair {k + 1}", k * tread, (k + 1) * tread,
                          round(-riser * (k + 1), 4)) for k in range(4)]
        regions.append(region("stairwell floor", 4 * tread, None, round(-riser * 5, 4)))
    else:
        depth = rng.uniform(0.055, 0.19) if kind == "step down" else rng.uniform(0.3, 1.0)
        regions = [region(kind, 0.0, None, round(-depth, 4))]
    # up to the edge: the last pose 0.46-0.69 m from it on the axis, 0.06 m more or less
    # beside it (0.1 m off the axis), so the footprint (0.25 m) stops 0.15-0.5 m short
    step, stop = rng.uniform(0.25, 0.4), rng.uniform(0.46, 0.69)
    last = near - stop / math.cos(angle)
    poses = [[round(x, 3), round(float(rng.uniform(-0.1, 0.1)), 3),
              round(float(rng.uniform(-0.06, 0.06)), 4)]
             for x in last - step * np.arange(int(last / step), -1, -1)]
    return _room(f"approach room {seed}", f"approach_room({seed})", round(far + 1.1, 4),
                 round(width, 3), 0.8, [], regions, poses)


# the drawn rooms' families by `bench_hazards`' flag (`--random N`, ...): the drop-off and
# ramp measures
FAMILIES = {"random": random_room, "mixed": mixed_room, "step": step_room, "ramp": ramp_room,
            "terrain": terrain_room, "approach": approach_room}
