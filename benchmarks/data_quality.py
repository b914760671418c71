"""Data quality benchmark (`motion-envs bench data`).

Writes `benchmarks/results/data_quality.md` and `data_quality_retarget.png`:
clips, subjects and minutes per split; retargeting error; the data's own foot
skating at 30 fps by WANDR's definition (the "ground truth" FS later tables
compare with); BVH reader speed against bvhio; FK + marker throughput against
mannequin-x's numpy `joint_transforms`.
"""

from __future__ import annotations

import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mannequin  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch.utils import benchmark  # noqa: E402

from benchmarks.machine import machine_line  # noqa: E402
from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.body import PARENTS, BodyModel  # noqa: E402
from motion_envs.body.markers import foot_vertex_ids, marker_ids  # noqa: E402
from motion_envs.data.build import build  # noqa: E402
from motion_envs.data.bvh import read_bvh  # noqa: E402
from motion_envs.data.canonical import body_tensors  # noqa: E402
from motion_envs.data.dataset import MotionDataset  # noqa: E402
from motion_envs.data.paths import default_mocap_dir  # noqa: E402
from motion_envs.data.resample import resample_source  # noqa: E402
from motion_envs.data.retarget import RetargetConfig, retarget  # noqa: E402
from motion_envs.data.skeleton_maps import match_skeleton  # noqa: E402
from motion_envs.data.splits import SPLITS  # noqa: E402
from motion_envs.metrics import foot_skating  # noqa: E402
from motion_envs.plots import save  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
FK_BATCH = 4096
PLOT_CLIP = "cmu/07_01.bvh"


def fk_throughput(min_run_time: float = 3.0) -> dict[str, float]:
    """Poses/s (median of `torch.utils.benchmark` blocks) of torch FK + 67 markers and of
    mannequin-x's numpy `joint_transforms`, on the same batch in the same run."""
    body = BodyModel()
    generator = torch.Generator().manual_seed(0)
    transl = torch.randn(FK_BATCH, 3, generator=generator)
    orient = torch.randn(FK_BATCH, 3, generator=generator)
    pose = 0.5 * torch.randn(FK_BATCH, 21, 3, generator=generator)
    reference = mannequin.Mannequin("wooden")
    params = reference.rest_pose(batch_dims=(FK_BATCH,))
    params["body_pose"] = pose.numpy()
    params["global_rotation"] = orient.numpy()
    scope = {"body": body, "transl": transl, "orient": orient, "pose": pose, "markers": marker_ids(),
             "reference": reference, "params": params}  # fmt: skip
    threads = torch.get_num_threads()
    with torch.inference_mode():
        ours = benchmark.Timer("body.skin(body(transl, orient, pose), markers)", globals=scope, num_threads=threads)
        ours_fk = benchmark.Timer("body(transl, orient, pose)", globals=scope, num_threads=threads)
        theirs = benchmark.Timer("reference.joint_transforms(params)", globals=scope, num_threads=threads)
        seconds = {
            "ours": ours.blocked_autorange(min_run_time=min_run_time).median,
            "ours_joints": ours_fk.blocked_autorange(min_run_time=min_run_time).median,
            "mannequin": theirs.blocked_autorange(min_run_time=min_run_time).median,
        }
    return {name: FK_BATCH / value for name, value in seconds.items()}


def reader_speed(mocap_dir: Path, names: tuple[str, ...] = ("cmu/07_01.bvh", "cmu/13_01.bvh")) -> list[str]:
    """Rows comparing our BVH reader with bvhio (if installed): seconds and joint agreement."""
    try:
        import bvhio
    except ImportError:
        return ["| bvhio | not installed | | |"]
    rows = []
    for name in names:
        path = mocap_dir / name
        start = time.perf_counter()
        motion = read_bvh(path)
        ours = time.perf_counter() - start
        positions, _ = motion.global_transforms()
        start = time.perf_counter()
        root = bvhio.readAsHierarchy(str(path))
        theirs = time.perf_counter() - start
        frame = motion.num_frames // 2
        root.loadPose(frame)
        layout = {joint.Name: np.array(joint.PositionWorld) for joint, _, _ in root.layout()}
        index = {n: i for i, n in enumerate(motion.skeleton.names)}
        gap = max(np.abs(layout[n] - positions[frame, index[n]]).max() for n in layout if n in index)
        rows.append(f"| {name} ({motion.num_frames} frames) | {ours * 1e3:.0f} ms | {theirs * 1e3:.0f} ms "
                    f"(load only) | {gap:.1e} cm |")  # fmt: skip
    return rows


def skating_by_clip(dataset: MotionDataset, body: BodyModel) -> np.ndarray:
    """(C,) FS of each clip (fraction of frame transitions that skate)."""
    feet_ids = foot_vertex_ids()
    values = []
    with torch.inference_mode():
        for index in dataset.clip_ids():
            clip = dataset.clip(index)
            feet = body.skin(body(*body_tensors(clip)), feet_ids)
            values.append(foot_skating(feet).float().mean().item())
    return np.array(values)


def retarget_figure(mocap_dir: Path, destination: Path) -> None:
    """Source skeleton (grey) beside the retargeted body (blue) at a few frames of one clip."""
    body = BodyModel()
    captured = read_bvh(mocap_dir / PLOT_CLIP)
    mapping = match_skeleton(captured.skeleton.names)
    source = resample_source(captured.frames(mapping.leading_frames_to_skip), 30)
    result = retarget(source, mapping, body, "07_01", "07", RetargetConfig())
    with torch.inference_mode():
        joints = body(*body_tensors(result.motion)).joints.numpy()
    frames = np.linspace(0, len(joints) - 1, 5).astype(int)
    figure, axes = plt.subplots(1, len(frames), figsize=(3 * len(frames), 4.5), sharey=True)
    for axis, frame in zip(axes, frames):
        src = result.source_positions[frame]
        pelvis = joints[frame, 0]
        for joint, parent in enumerate(captured.skeleton.parents):
            name = captured.skeleton.names[joint]
            if parent >= 0 and (not name.endswith("_end") or name.endswith("Foot_end")):  # no finger/eye tips
                segment = src[[parent, joint]] - src[0] + pelvis
                axis.plot(segment[:, 1] - 0.5, segment[:, 2], color="0.55", lw=2)
        for joint, parent in enumerate(PARENTS[1:], start=1):
            segment = joints[frame, [parent, joint]]
            axis.plot(segment[:, 1] + 0.5, segment[:, 2], color="tab:blue", lw=2)
        axis.set_title(f"frame {frame} (30 fps)")
        axis.set_aspect("equal")
        axis.set_xticks([])
    figure.suptitle(f"{PLOT_CLIP}: source skeleton (grey, left) vs retargeted body (blue, right), side view")
    save(figure, destination, dpi=90)


def main(mocap_dir: Path | None = None, cache_dir: Path | None = None, subsets: tuple[str, ...] = ("cmu",)) -> int:
    mocap_dir = Path(mocap_dir or default_mocap_dir() or "")
    RESULTS.mkdir(parents=True, exist_ok=True)
    report = build(mocap_dir=mocap_dir, cache_dir=cache_dir, subsets=subsets)
    dataset = MotionDataset.load(report.caches[30])
    body = BodyModel()
    skating = skating_by_clip(dataset, body)
    arrays = dataset.arrays
    lengths = np.diff(arrays["clip_start"]) / dataset.fps
    lines = [
        "# Data quality",
        "",
        f"Command: `motion-envs bench data --subset {' --subset '.join(subsets)}`. {machine_line()}",
        f"Source: `{mocap_dir}` subsets {list(subsets)}; cache `{report.caches[30].name}`. "
        f"{len(report.failures)} clips skipped.",
        "",
        "## Splits (30 fps cache)",
        "",
        "| split | clips | subjects | minutes | FS (WANDR, 30 fps) |",
        "|---|---|---|---|---|",
    ]
    for split in SPLITS:
        ids = dataset.clip_ids(split)
        frames = np.diff(arrays["clip_start"])[ids]
        fs = float(np.sum(skating[ids] * (frames - 1)) / np.sum(frames - 1)) if ids else float("nan")
        subjects = sorted(set(arrays["clip_subject"][ids]))
        lines.append(f"| {split} | {len(ids)} | {', '.join(subjects)} | {lengths[ids].sum() / 60:.2f} | {fs:.3f} |")
    frames = np.diff(arrays["clip_start"])
    overall = float(np.sum(skating * (frames - 1)) / np.sum(frames - 1))
    lines.append(f"| all | {len(frames)} | {len(set(arrays['clip_subject']))} | {lengths.sum() / 60:.2f} | {overall:.3f} |")
    errors = arrays["retarget_error_mean"] * 100
    worst = int(np.argmax(errors))
    lines += [
        "",
        "FS: fraction of frame transitions in which the lowest foot vertex moves more than 0.66 cm",
        "horizontally by the next frame (WANDR's definition, no height gating).",
        "",
        "## Retargeting error (cm, per clip mean over frames and mapped joints)",
        "",
        "| mean over clips | p95 over clips | max clip | clips > 6 cm |",
        "|---|---|---|---|",
        f"| {errors.mean():.2f} | {np.percentile(errors, 95):.2f} | {errors.max():.2f} ({arrays['clip_name'][worst]}) "
        f"| {int((errors > 6).sum())} |",
        "",
        "Error: distance between the body's joints and the scaled source joints carrying their constant",
        "rest-placement offsets (see `motion_envs/data/retarget.py`). Figure: `data_quality_retarget.png`.",
        "",
        "## BVH reader (ours, vectorised numpy) vs bvhio",
        "",
        "| file | ours (parse + FK-ready) | bvhio readAsHierarchy | max joint gap (mid frame) |",
        "|---|---|---|---|",
        *reader_speed(mocap_dir),
        "",
        "## Forward kinematics + 67 markers, batch 4,096 poses, CPU",
        "",
    ]
    speed = fk_throughput()
    lines += [
        "| implementation | poses/s | ratio |",
        "|---|---|---|",
        f"| motion_envs torch FK + 67-marker skinning | {speed['ours']:,.0f} | {speed['ours'] / speed['mannequin']:.1f}x |",
        f"| motion_envs torch FK (22 joints) | {speed['ours_joints']:,.0f} | {speed['ours_joints'] / speed['mannequin']:.1f}x |",
        f"| mannequin-x numpy `joint_transforms` (joints only) | {speed['mannequin']:,.0f} | 1.0x |",
        "",
        "Median of `torch.utils.benchmark` blocks (3 s each), axis-angle input, float32, inference mode.",
        "mannequin-x computes all 54 joints (hands too) in float32 numpy. Target: >= 300,000 poses/s.",
    ]
    text = "\n".join(lines) + "\n"
    atomic_write(RESULTS / "data_quality.md", lambda file: file.write(text.encode()))
    retarget_figure(mocap_dir, RESULTS / "data_quality_retarget.png")
    print(text)
    return 0

