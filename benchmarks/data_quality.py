"""Data quality benchmark (`motion-envs bench data`).

Writes `benchmarks/results/data_quality.md`, `data_quality_retarget.png` and
`data_quality_feet.png`: clips, subjects and minutes per split; the data before
and after cleanup (`motion_envs.data.cleanup`) per split, by WANDR's FS and the
contact-aware FS (`metrics.loaded_foot_skating`), stance-ankle speed, GAMMA's
contact score, how far cleanup moved the joints and how still the locked points
hold; the same for clean-capture references (HDM05, CMU 35_01), raw, retargeted
and cleaned; retargeting error; BVH reader speed against bvhio; FK + marker
throughput against mannequin-x's numpy `joint_transforms`.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import mannequin  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch.utils import benchmark  # noqa: E402
from tqdm import tqdm  # noqa: E402

from benchmarks.machine import bench_command, data_options, machine_line  # noqa: E402
from motion_envs.atomic import atomic_write  # noqa: E402
from motion_envs.body import PARENTS, BodyModel, joint_index  # noqa: E402
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
from motion_envs.body.frames import Y_UP_TO_Z_UP  # noqa: E402
from motion_envs.body.markers import sole_vertex_ids  # noqa: E402
from motion_envs.data.asf_amc import read_amc, read_asf  # noqa: E402
from motion_envs.data.build import find_sources, load_clip  # noqa: E402
from motion_envs.data.cleanup import CleanupConfig, horizontal_speed, pelvis_tilt, straightness  # noqa: E402
from motion_envs.data.motion import BodyMotion  # noqa: E402
from motion_envs.metrics import contact_score, foot_skating, loaded_foot_skating, stance_ankle_speed  # noqa: E402
from motion_envs.plots import save  # noqa: E402
from motion_envs.data.paths import SHIPPED_SUBSETS  # noqa: E402

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


REFERENCES = {
    "HDM05 jogging, actor bk (clean capture)": "hdm05/HDM_bk_jog",
    "HDM05, all 93 clips (clean capture)": "hdm05/",
    "CMU 35_01 walk, original ASF/AMC (clean capture)": "cmu_extra/35/35_01",
    "CMU Daz-friendly walks (07, 08)": "cmu/0[78]_",
}
"""Reference sets for the cleanup table: label -> a regex on the clip's file path."""
WALKS = r"cmu/0[78]_"
"""CMU subjects 07 and 08: walks (the stance-ankle speed row of the issue)."""


@dataclass
class MotionFigures:
    """Per-clip measures: FS (WANDR), contact-aware FS, stance-ankle speed (m/s), GAMMA contact score, frames."""

    wandr_fs: float
    loaded_fs: float
    ankle_speed: float
    contact: float
    frames: int


def motion_figures(motion: BodyMotion, body: BodyModel) -> MotionFigures:
    """The measures of one clip of body motion (floor at z = 0 for the contact score)."""
    with torch.inference_mode():
        pose = body(*body_tensors(motion))
        feet = body.skin(pose, foot_vertex_ids())
        soles = body.skin(pose, sole_vertex_ids())
        markers = body.skin(pose, marker_ids())
        windows = markers[: len(markers) // 10 * 10].reshape(-1, 10, *markers.shape[1:])
        contact = contact_score(windows, motion.fps).mean().item() if len(windows) else float("nan")
        return MotionFigures(foot_skating(feet).float().mean().item(),
                             loaded_foot_skating(soles, motion.fps).float().mean().item(),
                             stance_ankle_speed(pose.joints[:, [7, 8]], motion.fps).item(), contact, motion.num_frames)  # fmt: skip


def source_figures(path: Path, skeleton: Path | None) -> MotionFigures:
    """Raw-source measures at 30 fps on its own joints (ankle and toe joints stand in for heel and toe)."""
    captured = read_amc(path, read_asf(skeleton)) if skeleton else read_bvh(path)
    mapping = match_skeleton(captured.skeleton.names, str(path))
    source = resample_source(captured.frames(mapping.leading_frames_to_skip), 30)
    positions = source.global_transforms()[0] * source.metres_per_unit @ Y_UP_TO_Z_UP.T
    names = source.skeleton.names
    soles = torch.as_tensor(positions[:, [names.index(mapping.joints[j]) for j in ("left_ankle", "left_foot", "right_ankle", "right_foot")]])
    return MotionFigures(float("nan"), loaded_foot_skating(soles, 30).float().mean().item(),
                         stance_ankle_speed(soles[:, [0, 2]], 30).item(), float("nan"), source.num_frames)  # fmt: skip


def weighted(figures: list[MotionFigures], field: str) -> float:
    """Frame-weighted mean of one measure (the median for the stance-ankle speed) over clips."""
    values = np.array([getattr(f, field) for f in figures])
    if field == "ankle_speed":
        return float(np.nanmedian(values)) if len(values) else float("nan")
    frames = np.array([f.frames for f in figures], dtype=float)
    keep = np.isfinite(values)
    return float(np.sum(values[keep] * frames[keep]) / frames[keep].sum()) if keep.any() else float("nan")


def figures_by_clip(dataset: MotionDataset, body: BodyModel) -> list[MotionFigures]:
    return [motion_figures(dataset.clip(index), body) for index in tqdm(dataset.clip_ids(), desc="measure", unit="clip")]


def cleanup_rows(clean: MotionDataset, raw: MotionDataset, body: BodyModel) -> list[str]:
    """Per split: the measures before and after cleanup, and what cleanup moved."""
    after, before = figures_by_clip(clean, body), figures_by_clip(raw, body)
    arrays = clean.arrays
    rows = []
    groups = {split: clean.clip_ids(split) for split in SPLITS} | {"all": clean.clip_ids()}
    walks = [i for i in clean.clip_ids() if re.match(WALKS, str(arrays["clip_file"][i]))]
    for label, ids in (*groups.items(), ("CMU walks (07, 08)", walks)):
        if not ids:
            continue
        pick = lambda figures: [figures[i] for i in ids]  # noqa: E731
        cells = [f"{weighted(pick(before), f):.3f} → {weighted(pick(after), f):.3f}" for f in ("wandr_fs", "loaded_fs", "ankle_speed", "contact")]
        shift = arrays["cleanup_shift_mean"][ids] * 100
        rows.append(f"| {label} | {len(ids)} | {' | '.join(cells)} | {np.average(shift, weights=[after[i].frames for i in ids]):.2f} / "
                    f"{arrays['cleanup_shift_max'][ids].max() * 100:.1f} | {np.median(arrays['lock_residual_max'][ids]) * 100:.2f} / "
                    f"{arrays['lock_residual_max'][ids].max() * 100:.1f} | {arrays['retarget_error_mean'][ids].mean() * 100:.2f} |")  # fmt: skip
    return rows


def posture(dataset: MotionDataset, index: int, body: BodyModel) -> tuple[float, float, float] | None:
    """One clip's walking posture: median head and pelvis height above the lowest ankle or toe joint over frames
    whose pelvis moves at 0.5-2 m/s on the ground, and median pelvis tilt (`cleanup.pelvis_tilt`) over frames with
    both legs straight (`CleanupConfig.upright_straightness`); None for a clip with less than 0.5 s of walking."""
    motion = dataset.clip(index)
    with torch.inference_mode():
        joints = body(*body_tensors(motion)).joints.double().numpy()
    speed = horizontal_speed(joints[:, :1], dataset.fps)[:, 0]
    walking = (speed >= 0.5) & (speed <= 2.0)
    if walking.sum() < 0.5 * dataset.fps:
        return None
    feet = joints[:, [joint_index(name) for name in ("left_ankle", "right_ankle", "left_foot", "right_foot")], 2].min(axis=1)
    upright = np.minimum(straightness(joints, "left"), straightness(joints, "right")) >= CleanupConfig().upright_straightness
    tilt = float(np.median(pelvis_tilt(joints)[upright])) if upright.any() else np.nan
    return (float(np.median((joints[:, joint_index("head"), 2] - feet)[walking])),
            float(np.median((joints[:, 0, 2] - feet)[walking])), tilt)  # fmt: skip


def posture_rows(clean: MotionDataset, raw: MotionDataset, body: BodyModel) -> list[str]:
    """Per source skeleton: walking posture before and after cleanup (median over clips), and the pelvis-tilt fix."""
    arrays = clean.arrays
    rows = []
    for skeleton in sorted(set(arrays["clip_skeleton"])):
        ids = [i for i in clean.clip_ids() if arrays["clip_skeleton"][i] == skeleton]
        pairs = [(posture(raw, i, body), posture(clean, i, body)) for i in ids]  # both caches hold the same clips in order
        pairs = [(b, a) for b, a in pairs if b is not None and a is not None]
        if not pairs:
            continue
        cells = [f"{np.nanmedian([b[k] for b, _ in pairs]):.{d}f} → {np.nanmedian([a[k] for _, a in pairs]):.{d}f}"
                 for k, d in ((0, 3), (1, 3), (2, 1))]  # fmt: skip
        fixes = arrays["pelvis_tilt_fix"][ids]
        rows.append(f"| {skeleton} | {len(pairs)} | {' | '.join(cells)} | {np.median(fixes):.1f} ({fixes.min():.1f}-{fixes.max():.1f}) |")
    return rows


def reference_rows(mocap_dir: Path, body: BodyModel) -> list[str]:
    """Clean-capture references and the Daz walks: raw source, retargeted, retargeted and cleaned."""
    sources = find_sources(mocap_dir)
    rows = []
    for label, pattern in REFERENCES.items():
        chosen = [s for s in sources if re.match(pattern, s.relative)]
        raw = [source_figures(s.path, s.skeleton) for s in chosen]
        retargeted = [motion_figures(load_clip(s, 30, body, RetargetConfig(), None), body) for s in tqdm(chosen, desc=label[:20])]
        cleaned = [motion_figures(load_clip(s, 30, body, RetargetConfig(), CleanupConfig()), body) for s in tqdm(chosen, desc=label[:20])]
        for stage, figures in (("raw source joints", raw), ("retargeted", retargeted), ("retargeted + cleanup", cleaned)):
            cells = " | ".join("–" if np.isnan(weighted(figures, f)) else f"{weighted(figures, f):.3f}" for f in ("wandr_fs", "loaded_fs", "ankle_speed", "contact"))
            rows.append(f"| {label} | {len(chosen)} | {stage} | {cells} |")
    return rows


def feet_figure(raw: MotionDataset, clean: MotionDataset, body: BodyModel, destination: Path, clip: str = "cmu/08_11") -> None:
    """One walk's sole points before and after cleanup: top view of the paths, heights over time."""
    figure, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for dataset, style, label in ((raw, ":", "before"), (clean, "-", "after")):
        motion = dataset.clip({str(n): i for i, n in enumerate(dataset.arrays["clip_name"])}[clip])
        with torch.inference_mode():
            soles = body.skin(body(*body_tensors(motion)), sole_vertex_ids()).numpy()
        time = np.arange(len(soles)) / dataset.fps
        for point, color in ((0, "tab:blue"), (1, "tab:cyan"), (2, "tab:red"), (3, "tab:orange")):
            axes[0].plot(soles[:, point, 0], soles[:, point, 1], style, color=color, lw=1.2)
            axes[1].plot(time, soles[:, point, 2] * 100, style, color=color, lw=1.2, label=f"{label} {'LLRR'[point]} {'heel toe'.split()[point % 2]}")
            speed = np.linalg.norm(np.gradient(soles[:, point, :2], axis=0), axis=-1) * dataset.fps
            axes[2].plot(time, speed, style, color=color, lw=1.0)
    axes[0].set(title=f"{clip}: sole paths, top view (dotted before, solid after)", xlabel="x (m)", ylabel="y (m)", aspect="equal")
    axes[1].set(title="sole point height (cm)", xlabel="s", ylim=(-5, 25))
    axes[1].legend(fontsize=6, ncol=2)
    axes[2].set(title="horizontal speed (m/s)", xlabel="s", ylim=(0, 3))
    save(figure, destination, dpi=90)


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


def timing_lines(mocap_dir: Path) -> list[str]:
    """The BVH reader against bvhio and FK + markers against mannequin-x, as Markdown lines."""
    speed_rows = reader_speed(mocap_dir)
    speed = fk_throughput()
    return [
        "## BVH reader (ours, vectorised numpy) vs bvhio",
        "",
        "| file | ours (parse + FK-ready) | bvhio readAsHierarchy | max joint gap (mid frame) |",
        "|---|---|---|---|",
        *speed_rows,
        "",
        "## Forward kinematics + 67 markers, batch 4,096 poses, CPU",
        "",
        "| implementation | poses/s | ratio |",
        "|---|---|---|",
        f"| motion_envs torch FK + 67-marker skinning | {speed['ours']:,.0f} | {speed['ours'] / speed['mannequin']:.1f}x |",
        f"| motion_envs torch FK (22 joints) | {speed['ours_joints']:,.0f} | {speed['ours_joints'] / speed['mannequin']:.1f}x |",
        f"| mannequin-x numpy `joint_transforms` (joints only) | {speed['mannequin']:,.0f} | 1.0x |",
        "",
        "Median of `torch.utils.benchmark` blocks (3 s each), axis-angle input, float32, inference mode.",
        "mannequin-x computes all 54 joints (hands too) in float32 numpy. Target: >= 300,000 poses/s.",
    ]


def main(mocap_dir: Path | None = None, cache_dir: Path | None = None, subsets: tuple[str, ...] = SHIPPED_SUBSETS,
         timing: bool = True) -> int:  # fmt: skip
    """`timing=False` (`--no-timing`) leaves out the reader and FK speed sections (for a machine that is busy)."""
    command = bench_command("data", {**data_options(mocap_dir, subsets), "no-timing": not timing})
    mocap_dir = Path(mocap_dir or default_mocap_dir() or "")
    RESULTS.mkdir(parents=True, exist_ok=True)
    report = build(mocap_dir=mocap_dir, cache_dir=cache_dir, subsets=subsets)
    raw_report = build(mocap_dir=mocap_dir, cache_dir=cache_dir, subsets=subsets, fps_list=(30,), cleanup=None)
    dataset = MotionDataset.load(report.caches[30])
    raw = MotionDataset.load(raw_report.caches[30])
    body = BodyModel()
    arrays = dataset.arrays
    lengths = np.diff(arrays["clip_start"]) / dataset.fps
    lines = [
        "# Data quality",
        "",
        f"Command: `{command}`. {machine_line()}",
        f"Source: `{mocap_dir}` subsets {list(subsets)}; cache `{report.caches[30].name}` (uncleaned: "
        f"`{raw_report.caches[30].name}`). {len(report.failures)} clips skipped.",
        "",
        "## Splits (30 fps cache)",
        "",
        "| split | clips | subjects | minutes |",
        "|---|---|---|---|",
    ]
    for split in SPLITS:
        ids = dataset.clip_ids(split)
        subjects = sorted(set(arrays["clip_subject"][ids]))
        lines.append(f"| {split} | {len(ids)} | {', '.join(subjects)} | {lengths[ids].sum() / 60:.2f} |")
    lines.append(f"| all | {len(lengths)} | {len(set(arrays['clip_subject']))} | {lengths.sum() / 60:.2f} |")
    lines += [
        "",
        "## Cleanup: before → after, per split (30 fps)",
        "",
        "| clips | n | FS (WANDR) | contact-aware FS | stance-ankle speed (m/s, median of clips) | GAMMA contact score "
        "| joints moved, cm (mean / max) | locked point drift, cm (median clip / worst clip) | retarget error (cm) |",
        "|---|---|---|---|---|---|---|---|---|",
        *cleanup_rows(dataset, raw, body),
        "",
        "## Posture: walking height and pelvis tilt, per source skeleton (30 fps)",
        "",
        "| skeleton | walking clips | head above feet (m) | pelvis above feet (m) | pelvis tilt (°) "
        "| tilt fix (°), median (range) over all its clips |",
        "|---|---|---|---|---|---|",
        *posture_rows(dataset, raw, body),
        "",
        "Before → after cleanup, medians over the clips with at least 0.5 s of walking (pelvis 0.5-2 m/s on the",
        "ground) of each clip's median over those frames; feet: the lowest ankle or toe joint. Pelvis tilt: the",
        "hips' midpoint -> spine1 from vertical (1° at rest) over frames with both legs straight. Cleanup turns",
        "back the pelvis of clips on a skeleton not their subject's own (`SkeletonMap.subject_skeleton`: the Daz",
        "files) to 14°, the subjects' own skeletons' (`motion_envs/data/cleanup.py`, step 3).",
        "",
        "## References: clean capture and the Daz walks (30 fps)",
        "",
        "| set | clips | stage | FS (WANDR) | contact-aware FS | stance-ankle speed (m/s) | GAMMA contact score |",
        "|---|---|---|---|---|---|---|",
        *reference_rows(mocap_dir, body),
        "",
        "FS (WANDR): fraction of frame transitions in which the lowest foot vertex moves more than 0.66 cm",
        "horizontally by the next frame (no height gating). Contact-aware FS (`metrics.loaded_foot_skating`): the",
        "lowest of the four sole points (heel, toe of each foot) is within 2.5 cm of the local floor (the lowest",
        "sole point within ±0.5 s) at both frames and moves faster than 0.2 m/s. On the raw sources the ankle and",
        "toe joints stand in for heel and toe (joints sit above the sole, so raw and body figures compare only",
        "roughly). Stance-ankle speed: the lower ankle's horizontal speed while it stays the lower one (median).",
        "GAMMA's contact score (Eq. 11) over 10-frame windows with the floor at z = 0 (retargeted-only clips keep",
        "the first frame's floor). Locked point drift: per clip the largest distance of a contact point from its",
        "lock target during a labelled contact. Joints moved: by foot locking (the floor levelling is a rigid",
        "turn of the whole clip and not counted). Figure: `data_quality_feet.png`.",
    ]
    errors = arrays["retarget_error_mean"] * 100
    worst = int(np.argmax(errors))
    lines += [
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
        ""
    ]
    lines += timing_lines(mocap_dir) if timing else ["## Reader and FK speed", "", "Not measured in this run (`--no-timing`)."]
    text = "\n".join(lines) + "\n"
    atomic_write(RESULTS / "data_quality.md", lambda file: file.write(text.encode()))
    retarget_figure(mocap_dir, RESULTS / "data_quality_retarget.png")
    feet_figure(raw, dataset, body, RESULTS / "data_quality_feet.png")
    print(text)
    return 0

