"""A small, vectorised BVH reader.

The hierarchy is parsed token by token (so errors carry a line number); the
motion block, which is nearly all of a file, is parsed in one `np.array` call
over its whitespace-split tokens, and Euler angles become matrices with
scipy's vectorised `Rotation.from_euler`. Against `bvhio` 1.5 (pure Python,
per-joint objects) on the CMU files this is about two orders of magnitude
faster with the same joint positions (see `benchmarks/results/data_quality.md`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from motion_envs.data.motion import MocapFormatError, SourceMotion, SourceSkeleton

_POSITION = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
_ROTATION = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}


def read_bvh(path: str | Path, metres_per_unit: float = 0.01) -> SourceMotion:
    """Read a BVH file.

    Args:
        path: the file.
        metres_per_unit: the file's length unit (BVH does not say; 0.01 for
            centimetres, as in the CMU "Daz-friendly" release).

    Raises:
        MocapFormatError: naming the file and line of the first problem.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="latin-1").splitlines()
    except OSError as error:
        raise MocapFormatError(path, None, f"cannot read file ({error})") from error
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[list[str]] = []
    stack: list[int] = []
    pending: int | None = None  # joint whose '{' we expect next
    in_end_site = False
    row = 0
    if not lines or lines[0].strip() != "HIERARCHY":
        raise MocapFormatError(path, 1, "expected 'HIERARCHY'")
    for row in range(1, len(lines)):
        tokens = lines[row].split()
        if not tokens:
            continue
        keyword, line_no = tokens[0], row + 1
        if keyword in ("ROOT", "JOINT"):
            if len(tokens) < 2:
                raise MocapFormatError(path, line_no, f"{keyword} without a name")
            if keyword == "ROOT" and names:
                raise MocapFormatError(path, line_no, "a second ROOT is not supported")
            if keyword == "JOINT" and not stack:
                raise MocapFormatError(path, line_no, "JOINT outside the root's braces")
            names.append(tokens[1])
            parents.append(stack[-1] if stack else -1)
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            pending = len(names) - 1
        elif keyword == "End":  # an end site becomes a joint "<parent>_end" without channels
            if not stack:
                raise MocapFormatError(path, line_no, "End Site outside a joint")
            names.append(f"{names[stack[-1]]}_end")
            parents.append(stack[-1])
            offsets.append([0.0, 0.0, 0.0])
            channels.append([])
            in_end_site, pending = True, len(names) - 1
        elif keyword == "{":
            if pending is None:
                raise MocapFormatError(path, line_no, "'{' without a joint")
            stack.append(pending)
            pending = None
        elif keyword == "}" and in_end_site:
            stack.pop()
            in_end_site = False
        elif keyword == "}":
            if not stack:
                raise MocapFormatError(path, line_no, "unbalanced '}'")
            stack.pop()
            if not stack:
                break
        elif keyword == "OFFSET":
            if len(tokens) != 4:
                raise MocapFormatError(path, line_no, "OFFSET needs three numbers")
            offsets[stack[-1]] = _floats(tokens[1:], path, line_no)
        elif keyword == "CHANNELS":
            count = _int(tokens[1] if len(tokens) > 1 else "", path, line_no)
            names_given = tokens[2:]
            unknown = [c for c in names_given if c not in _POSITION and c not in _ROTATION]
            if len(names_given) != count or unknown:
                raise MocapFormatError(path, line_no, f"bad CHANNELS line (unknown {unknown})")
            if in_end_site:
                raise MocapFormatError(path, line_no, "an End Site has no CHANNELS")
            channels[stack[-1]] = names_given
        else:
            raise MocapFormatError(path, line_no, f"unexpected {keyword!r} in HIERARCHY")
    if not names or stack:
        raise MocapFormatError(path, row + 1, "HIERARCHY ended before the root's closing '}'")

    motion_row = row + 1
    while motion_row < len(lines) and not lines[motion_row].strip():
        motion_row += 1
    header = [lines[i].strip() if i < len(lines) else "" for i in range(motion_row, motion_row + 3)]
    if header[0] != "MOTION":
        raise MocapFormatError(path, motion_row + 1, "expected 'MOTION'")
    if not header[1].startswith("Frames:"):
        raise MocapFormatError(path, motion_row + 2, "expected 'Frames: N'")
    if not header[2].startswith("Frame Time:"):
        raise MocapFormatError(path, motion_row + 3, "expected 'Frame Time: seconds'")
    num_frames = _int(header[1].split(":", 1)[1].strip(), path, motion_row + 2)
    frame_time = _floats(header[2].split(":", 1)[1].split(), path, motion_row + 3)[0]
    if frame_time <= 0:
        raise MocapFormatError(path, motion_row + 3, "Frame Time must be positive")

    data_start = motion_row + 3
    rows = [line for line in lines[data_start:] if line.strip()]
    width = sum(len(c) for c in channels)
    if len(rows) != num_frames:
        raise MocapFormatError(path, motion_row + 2, f"'Frames: {num_frames}' but {len(rows)} data rows")
    try:
        values = np.array(" ".join(rows).split(), dtype=np.float64)
    except ValueError:
        bad = next(i for i, line in enumerate(rows) if not _is_numeric(line))
        raise MocapFormatError(path, data_start + bad + 1, "non-numeric value in MOTION data") from None
    if values.size != num_frames * width:
        counts = [len(line.split()) for line in rows]
        bad = next(i for i, count in enumerate(counts) if count != width)
        raise MocapFormatError(path, data_start + bad + 1, f"expected {width} values per frame, got {counts[bad]}")
    values = values.reshape(num_frames, width)
    if not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise MocapFormatError(path, data_start + bad + 1, "non-finite value in MOTION data")
    return _assemble(path, names, parents, offsets, channels, values, frame_time, metres_per_unit)


def _assemble(path, names, parents, offsets, channels, values, frame_time, metres_per_unit) -> SourceMotion:
    num_frames = values.shape[0]
    rotations = np.broadcast_to(np.eye(3), (num_frames, len(names), 3, 3)).copy()
    root_positions = np.zeros((num_frames, 3))
    column = 0
    for joint, joint_channels in enumerate(channels):
        positions = [(i, _POSITION[c]) for i, c in enumerate(joint_channels) if c in _POSITION]
        order = "".join(_ROTATION[c] for c in joint_channels if c in _ROTATION)
        block = values[:, column : column + len(joint_channels)]
        column += len(joint_channels)
        if joint == 0:
            for index, axis in positions:
                root_positions[:, axis] = block[:, index]
        if order:
            angles = block[:, [i for i, c in enumerate(joint_channels) if c in _ROTATION]]
            rotations[:, joint] = Rotation.from_euler(order, angles, degrees=True).as_matrix()  # intrinsic
    skeleton = SourceSkeleton(tuple(names), tuple(parents), np.asarray(offsets, dtype=np.float64))
    return SourceMotion(path, skeleton, 1.0 / frame_time, root_positions, rotations, metres_per_unit)


def _floats(tokens: list[str], path: Path, line: int) -> list[float]:
    try:
        return [float(t) for t in tokens]
    except ValueError:
        raise MocapFormatError(path, line, f"expected numbers, got {' '.join(tokens)!r}") from None


def _int(token: str, path: Path, line: int) -> int:
    try:
        return int(token)
    except ValueError:
        raise MocapFormatError(path, line, f"expected an integer, got {token!r}") from None


def _is_numeric(line: str) -> bool:
    try:
        np.array(line.split(), dtype=np.float64)
    except ValueError:
        return False
    return True
