"""Acclaim ASF (skeleton) + AMC (motion) reader, CMU's original format.

Each ASF bone becomes a joint at the bone's start, so the result has the same
shape as a BVH (`SourceMotion`). A bone's local rotation is C·M·C⁻¹, where C
is the bone's `axis` rotation and M the AMC rotation (both applied as
extrinsic rotations in the order listed), and its children sit at
`length · direction` from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from motion_envs.data.motion import MocapFormatError, SourceMotion, SourceSkeleton

INCH = 0.0254


@dataclass(frozen=True)
class AsfSkeleton:
    """A parsed ASF file: the joint skeleton plus what is needed to read its AMC files."""

    path: Path
    skeleton: SourceSkeleton
    axes: np.ndarray  # (J, 3, 3) C per joint
    dofs: tuple[tuple[str, ...], ...]  # per joint, e.g. ("rx", "rz"); root ("tx", ..., "rz")
    metres_per_unit: float


def read_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF file; raises MocapFormatError naming file and line."""
    path = Path(path)
    lines = _read_lines(path)
    length_unit, angle_in_degrees = 1.0, True
    bones: dict[str, dict] = {}
    order: list[str] = ["root"]
    root = {"dof": ("tx", "ty", "tz", "rx", "ry", "rz"), "axis": np.eye(3), "direction": np.zeros(3), "length": 0.0}
    hierarchy: dict[str, list[str]] = {}
    section, current, row = "", None, 0
    for row, line in enumerate(lines):
        tokens = line.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        line_no = row + 1
        if tokens[0].startswith(":"):
            section = tokens[0]
            continue
        if section == ":units" and tokens[0] == "length":
            length_unit = _number(tokens, 1, path, line_no)
        elif section == ":units" and tokens[0] == "angle":
            angle_in_degrees = tokens[1].lower().startswith("deg")
        elif section == ":root" and tokens[0] == "order":
            root["dof"] = tuple(t.lower() for t in tokens[1:])
        elif section == ":root" and tokens[0] == "orientation":
            root["axis"] = Rotation.from_euler("xyz", [_number(tokens, i, path, line_no) for i in (1, 2, 3)],
                                               degrees=angle_in_degrees).as_matrix()  # fmt: skip
        elif section == ":bonedata":
            if tokens[0] == "begin":
                current = {"dof": (), "axis": np.eye(3), "line": line_no}
            elif current is None:
                raise MocapFormatError(path, line_no, f"{tokens[0]!r} outside a begin/end block")
            elif tokens[0] == "end":
                if "name" not in current or "direction" not in current or "length" not in current:
                    raise MocapFormatError(path, line_no, "bone without name, direction or length")
                bones[current["name"]] = current
                order.append(current["name"])
                current = None
            elif tokens[0] == "name":
                current["name"] = tokens[1]
            elif tokens[0] == "direction":
                current["direction"] = np.array([_number(tokens, i, path, line_no) for i in (1, 2, 3)])
            elif tokens[0] == "length":
                current["length"] = _number(tokens, 1, path, line_no)
            elif tokens[0] == "axis":
                angles = [_number(tokens, i, path, line_no) for i in (1, 2, 3)]
                axis_order = tokens[4].lower() if len(tokens) > 4 else "xyz"
                current["axis"] = Rotation.from_euler(axis_order, angles, degrees=angle_in_degrees).as_matrix()
            elif tokens[0] == "dof":
                current["dof"] = tuple(t.lower() for t in tokens[1:])
        elif section == ":hierarchy" and tokens[0] not in ("begin", "end"):
            for child in tokens[1:]:
                if child not in bones:
                    raise MocapFormatError(path, line_no, f"hierarchy names unknown bone {child!r}")
            hierarchy[tokens[0]] = tokens[1:]
    if not bones:
        raise MocapFormatError(path, None, "no :bonedata bones found")
    parent_of = {child: parent for parent, children in hierarchy.items() for child in children}
    missing = [name for name in order[1:] if name not in parent_of]
    if missing:
        raise MocapFormatError(path, None, f"bones missing from :hierarchy: {missing}")
    joints = _topological(order, parent_of)
    bones["root"] = root
    offsets = np.zeros((len(joints), 3))
    for index, name in enumerate(joints[1:], start=1):
        parent = bones[parent_of[name]]
        offsets[index] = parent["direction"] * parent["length"] if parent_of[name] != "root" else 0.0
    skeleton = SourceSkeleton(
        tuple(joints), tuple(-1 if n == "root" else joints.index(parent_of[n]) for n in joints), offsets
    )
    return AsfSkeleton(
        path,
        skeleton,
        np.stack([bones[n]["axis"] for n in joints]),
        tuple(bones[n]["dof"] for n in joints),
        INCH / length_unit,
    )


def read_amc(path: str | Path, asf: AsfSkeleton, fps: float = 120.0) -> SourceMotion:
    """Read an AMC file against its skeleton (AMC does not store a rate: CMU/HDM05 use 120 fps)."""
    path = Path(path)
    lines = _read_lines(path)
    names = asf.skeleton.names
    index = {name: i for i, name in enumerate(names)}
    frames: list[dict[str, list[float]]] = []
    for row, line in enumerate(lines):
        tokens = line.split()
        if not tokens or tokens[0].startswith(("#", ":")):
            continue
        if tokens[0].isdigit() and len(tokens) == 1:
            frames.append({})
            continue
        if not frames:
            raise MocapFormatError(path, row + 1, "values before the first frame number")
        if tokens[0] not in index:
            raise MocapFormatError(path, row + 1, f"bone {tokens[0]!r} is not in {asf.path.name}")
        expected = len(asf.dofs[index[tokens[0]]])
        if len(tokens) - 1 != expected:
            raise MocapFormatError(path, row + 1, f"{tokens[0]} needs {expected} values, got {len(tokens) - 1}")
        values = _numbers(tokens[1:], path, row + 1)
        frames[-1][tokens[0]] = values
    if not frames:
        raise MocapFormatError(path, None, "no frames")
    num_frames = len(frames)
    rotations = np.broadcast_to(np.eye(3), (num_frames, len(names), 3, 3)).copy()
    root_positions = np.zeros((num_frames, 3))
    for joint, name in enumerate(names):
        dofs = asf.dofs[joint]
        if not dofs:
            continue
        values = np.array([frame.get(name, [0.0] * len(dofs)) for frame in frames])
        translation = [i for i, d in enumerate(dofs) if d.startswith("t")]
        rotation = [i for i, d in enumerate(dofs) if d.startswith("r")]
        if translation:
            root_positions[:, ["xyz".index(dofs[i][1]) for i in translation]] = values[:, translation]
        if rotation:
            order = "".join(dofs[i][1] for i in rotation)
            moving = Rotation.from_euler(order, values[:, rotation], degrees=True).as_matrix()
            axis = asf.axes[joint]
            rotations[:, joint] = axis @ moving @ axis.T
    return SourceMotion(path, asf.skeleton, fps, root_positions, rotations, asf.metres_per_unit)


def _topological(order: list[str], parent_of: dict[str, str]) -> list[str]:
    joints = ["root"]
    while len(joints) < len(order):
        joints += [name for name in order if name not in joints and parent_of.get(name) in joints]
    return joints


def _read_lines(path: Path) -> list[str]:
    try:
        return path.read_text(encoding="latin-1").splitlines()
    except OSError as error:
        raise MocapFormatError(path, None, f"cannot read file ({error})") from error


def _number(tokens: list[str], position: int, path: Path, line: int) -> float:
    if position >= len(tokens):
        raise MocapFormatError(path, line, f"missing value in {' '.join(tokens)!r}")
    return _numbers([tokens[position]], path, line)[0]


def _numbers(tokens: list[str], path: Path, line: int) -> list[float]:
    try:
        values = [float(t) for t in tokens]
    except ValueError:
        raise MocapFormatError(path, line, f"expected numbers, got {' '.join(tokens)!r}") from None
    if not np.all(np.isfinite(values)):
        raise MocapFormatError(path, line, "non-finite value")
    return values
