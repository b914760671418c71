"""AMASS-style `.npz` reader (SMPL-H/SMPL-X parameters) into `BodyMotion`.

Keys: `trans` (T, 3); either `root_orient` (T, 3) + `pose_body` (T, 63) or
`poses` (T, >= 66, whose first 66 values are root + 21 body joints);
`mocap_framerate` (or `mocap_frame_rate`). AMASS is Z up: its root rotation
R_a already lifts SMPL's Y-up body to Z up, so our global_orient is
R_a · Y_UP_TO_Z_UPᵀ. Pass `up_axis="y"` for files kept Y up. SMPL's `trans`
is added to the rest pelvis, so our pelvis position is trans + J_pelvis
(mannequin-x's neutral rest pelvis; the file's own betas are not used).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import roma
import torch

from motion_envs.body.frames import Y_UP_TO_Z_UP
from motion_envs.body.skeleton import rest_body
from motion_envs.data.motion import BodyMotion, MocapFormatError


def read_amass_npz(path: str | Path, up_axis: str = "z", subject: str = "") -> BodyMotion:
    """Read one AMASS-style motion file; raises MocapFormatError naming the problem."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except Exception as error:  # numpy raises OSError, ValueError, zipfile.BadZipFile, EOFError ...
        raise MocapFormatError(path, None, f"not a readable npz ({type(error).__name__}: {error})") from error
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be 'y' or 'z', got {up_axis!r}")
    rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in arrays), None)
    if "trans" not in arrays or rate_key is None:
        raise MocapFormatError(path, None, f"needs 'trans' and 'mocap_framerate'; has {sorted(arrays)}")
    rate = np.asarray(arrays[rate_key])
    if rate.size != 1 or not np.issubdtype(rate.dtype, np.number) or not np.isfinite(rate).all() or float(rate) <= 0:
        raise MocapFormatError(path, None, f"{rate_key} must be one positive number, got {rate.tolist()!r}")
    trans = np.asarray(arrays["trans"], dtype=np.float64)
    if "root_orient" in arrays and "pose_body" in arrays:
        root, body = arrays["root_orient"], arrays["pose_body"][:, :63]
    elif "poses" in arrays and arrays["poses"].shape[-1] >= 66:
        root, body = arrays["poses"][:, :3], arrays["poses"][:, 3:66]
    else:
        raise MocapFormatError(path, None, "needs 'root_orient' + 'pose_body', or 'poses' with >= 66 values")
    frames = trans.shape[0]
    if trans.shape != (frames, 3) or root.shape != (frames, 3) or body.shape != (frames, 63):
        raise MocapFormatError(
            path, None, f"shapes disagree: trans {trans.shape}, root {root.shape}, body {body.shape}"
        )
    if not (np.isfinite(trans).all() and np.isfinite(root).all() and np.isfinite(body).all()):
        raise MocapFormatError(path, None, "non-finite values")
    lift = np.eye(3) if up_axis == "z" else Y_UP_TO_Z_UP
    to_world = torch.as_tensor(Y_UP_TO_Z_UP)
    root_rotation = torch.as_tensor(lift) @ roma.rotvec_to_rotmat(torch.as_tensor(root, dtype=torch.float64))
    global_orient = roma.rotmat_to_rotvec(root_rotation @ to_world.T).numpy()
    pelvis_rest = rest_body().offsets[0] @ Y_UP_TO_Z_UP  # back in SMPL's own axes
    transl = (trans + pelvis_rest) @ lift.T
    return BodyMotion(
        name=path.stem,
        subject=subject or path.parent.name,
        fps=float(rate),
        transl=transl,
        global_orient=global_orient,
        body_pose=np.asarray(body, dtype=np.float64).reshape(frames, 21, 3),
        info={"skeleton": "AMASS npz"},
    )
