"""`motion-envs data build`: mocap folder -> retargeted, cleaned, canonical body motion cache.

One `.npz` per frame rate, named by a content hash of the source files, the
data code and the settings, so an unchanged rebuild only re-hashes and
returns. Clips that fail to parse or retarget, for any reason, are reported
with their file and reason and listed in the cache (`failures`), never silently
dropped, and the rest are built; every clip's values are checked finite (in
float32, as cached) and plausible (`check_plausible`) before they enter the cache.
Cleanup (`motion_envs.data.cleanup`: contacts, floor, foot locking) is on by
default and part of the cache key; `cleanup=None` (`--no-cleanup`) builds the
uncleaned data to compare. The cache holds each frame's sole contacts
(`contacts`, (T, 4) bool, `SOLE_POINTS` order; all False without cleanup) and the degrees each clip's pelvis
was turned back (`pelvis_tilt_fix`, cleanup step 3).
A killed build resumes: each finished clip (or its failure) is kept in a part
file beside the cache (`<cache>.parts/`), which goes once the cache is written.
"""

from __future__ import annotations

import hashlib
import pickle
import shutil
import sys
from dataclasses import dataclass, field
from importlib.metadata import version
from pathlib import Path

import numpy as np
from tqdm import tqdm

from motion_envs.atomic import atomic_write
from motion_envs.body import BodyModel
from motion_envs.data.amass import read_amass_npz
from motion_envs.data.asf_amc import read_amc, read_asf
from motion_envs.data.bvh import read_bvh
from motion_envs.body.markers import SOLE_POINTS
from motion_envs.data.canonical import canonicalise
from motion_envs.data.cleanup import CleanupConfig, clean
from motion_envs.data.motion import BodyMotion, MocapFormatError
from motion_envs.data.paths import default_cache_dir, default_mocap_dir
from motion_envs.data.resample import resample_body, resample_source
from motion_envs.data.retarget import RetargetConfig, retarget
from motion_envs.data.skeleton_maps import UnknownSkeletonError, match_skeleton
from motion_envs.data.splits import split_of

CACHE_CODE = (
    "data/amass.py", "data/asf_amc.py", "data/build.py", "data/bvh.py", "data/canonical.py", "data/cleanup.py",
    "data/motion.py", "data/resample.py", "data/retarget.py", "data/skeleton_maps.py",
    "data/splits.py", "body/frames.py", "body/markers.py", "body/skeleton.py",
)  # fmt: skip
"""Modules whose code decides the cache's content (the FK implementation changes speed only)."""
MAX_EXTENT = 1000.0
"""Largest plausible pelvis distance from the origin (m): a capture volume is tens of metres; a clip beyond a
kilometre holds garbage (a BVH of 1e300 offsets once became inf in the cache)."""
DEFAULT_FPS = (30, 40)
"""WANDR runs at 30 fps, GAMMA at 40 fps."""
CACHE_FORMAT = 2
"""2: per-frame contacts and per-clip cleanup figures."""


@dataclass(frozen=True)
class ClipSource:
    """One motion file found in the mocap folder (`skeleton` is the ASF for an AMC)."""

    path: Path
    relative: str
    subject: str
    skeleton: Path | None = None


@dataclass
class BuildReport:
    """What a build did: cache paths per fps, clips written, failures (file: reason)."""

    caches: dict[int, Path] = field(default_factory=dict)
    clips: int = 0
    failures: list[str] = field(default_factory=list)
    rebuilt: bool = False


def find_sources(mocap_dir: Path, subsets: tuple[str, ...] | None = None) -> list[ClipSource]:
    """Every .bvh, .amc (with its .asf) and .npz under `mocap_dir` (or its `subsets` folders)."""
    mocap_dir = Path(mocap_dir)
    if not mocap_dir.is_dir():
        raise FileNotFoundError(f"mocap folder {mocap_dir} does not exist")
    roots = [mocap_dir / s for s in subsets] if subsets else [mocap_dir]
    for root in roots:
        if not root.is_dir():
            present = sorted(p.name for p in mocap_dir.iterdir() if p.is_dir())
            raise FileNotFoundError(f"subset folder {root} does not exist; subfolders: {present}")
    found: list[ClipSource] = []
    for root in roots:
        for path in sorted(root.rglob("*")):
            suffix = path.suffix.lower()
            relative = path.relative_to(mocap_dir).as_posix()
            if suffix == ".bvh":
                found.append(ClipSource(path, relative, path.stem.split("_")[0]))
            elif suffix == ".npz":
                found.append(ClipSource(path, relative, path.parent.name))
            elif suffix == ".amc":
                asf = _asf_for(path)
                found.append(ClipSource(path, relative, asf.stem if asf else path.stem, asf))
    return found


def _asf_for(amc: Path) -> Path | None:
    """The .asf beside `amc` whose name is the longest prefix of the AMC's name."""
    candidates = [p for p in amc.parent.glob("*") if p.suffix.lower() == ".asf" and amc.stem.startswith(p.stem)]
    return max(candidates, key=lambda p: len(p.stem)) if candidates else None


def content_hash(sources: list[ClipSource], fps: int, retarget_config: RetargetConfig,
                 cleanup: CleanupConfig | None = CleanupConfig()) -> str:  # fmt: skip
    """sha256 over the source bytes, `CACHE_CODE`, mannequin-x's version and the settings."""
    digest = hashlib.sha256(f"{CACHE_FORMAT}|{fps}|{retarget_config}|{cleanup}|{version('mannequin-x')}".encode())
    package = Path(__file__).resolve().parents[1]
    for code in CACHE_CODE:
        digest.update((package / code).read_bytes())
    for source in sources:
        digest.update(source.relative.encode())
        for path in (source.path, source.skeleton):
            if path is not None:
                digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()


def load_clip(source: ClipSource, fps: int, body: BodyModel, retarget_config: RetargetConfig,
              cleanup: CleanupConfig | None = CleanupConfig()) -> BodyMotion:  # fmt: skip
    """Read, resample, retarget (for skeletal mocap), clean (unless `cleanup` is None) and canonicalise one clip.

    `info` gains `retarget_error` (T, 22) and, when cleaned, `contacts` (T, 4), `cleanup_shift` (T, 22),
    `lock_residual` (T, 4) and `pelvis_tilt_fix` (degrees; a skeleton not the subject's own) (see
    `motion_envs.data.cleanup.CleanupResult`)."""
    name = Path(source.relative).with_suffix("").as_posix()
    mapping = None
    if source.path.suffix.lower() == ".npz":
        motion = resample_body(read_amass_npz(source.path, subject=source.subject), fps)
        motion.info["retarget_error"] = np.zeros((motion.num_frames, 22))
    else:
        if source.path.suffix.lower() == ".amc":
            if source.skeleton is None:
                raise MocapFormatError(source.path, None, "no .asf skeleton beside it whose name prefixes it")
            captured = read_amc(source.path, read_asf(source.skeleton))
        else:
            captured = read_bvh(source.path)
        mapping = match_skeleton(captured.skeleton.names, str(source.path))
        captured = captured.frames(mapping.leading_frames_to_skip)
        result = retarget(resample_source(captured, fps), mapping, body, name, source.subject, retarget_config)
        motion = result.motion
        motion.info["retarget_error"] = result.joint_error
    if cleanup is None:
        motion.info["contacts"] = np.zeros((motion.num_frames, len(SOLE_POINTS)), dtype=bool)
        return canonicalise(motion, body)
    check_plausible(motion, source.relative)  # garbage (inf, 1e300) is refused before cleanup computes on it
    cleaned = clean(motion, body, cleanup, correct_pelvis_tilt=mapping is not None and not mapping.subject_skeleton)
    cleaned.motion.info.update(contacts=cleaned.contacts, cleanup_shift=cleaned.joint_shift,
                               lock_residual=cleaned.lock_residual, pelvis_tilt_fix=cleaned.pelvis_tilt_fix)  # fmt: skip
    return canonicalise(cleaned.motion, body, ground_first_frame=False)  # cleanup put the floor at z = 0


def check_plausible(motion: BodyMotion, relative: str) -> None:
    """Raise ValueError naming `relative` unless the motion's arrays are finite as float32 and its pelvis stays
    within `MAX_EXTENT` m of the origin."""
    if motion.num_frames < 2:
        raise ValueError(f"{relative}: {motion.num_frames} frame(s) after resampling; a clip needs at least 2")
    for name in ("transl", "global_orient", "body_pose"):
        with np.errstate(over="ignore"):  # beyond float32's range becomes inf: refused here
            cached = np.asarray(getattr(motion, name), dtype=np.float32)
        if not np.isfinite(cached).all():
            raise ValueError(f"{relative}: non-finite {name} (values beyond float32's range or NaN)")
    reach = float(np.abs(motion.transl).max())
    if reach > MAX_EXTENT:
        raise ValueError(f"{relative}: the pelvis goes {reach:.3g} m from the origin (implausible; at most {MAX_EXTENT:g} m)")


def _failure_summary(failures: list[str], shown: int = 20) -> str:
    lines = failures[:shown] + ([f"... and {len(failures) - shown} more"] if len(failures) > shown else [])
    return "\n  ".join(lines)


def build(
    mocap_dir: Path | None = None,
    cache_dir: Path | None = None,
    subsets: tuple[str, ...] | None = None,
    fps_list: tuple[int, ...] = DEFAULT_FPS,
    retarget_config: RetargetConfig = RetargetConfig(),
    progress: bool = True,
    cleanup: CleanupConfig | None = CleanupConfig(),
) -> BuildReport:
    """Build (or find) the cache for each frame rate; `cleanup=None` skips the cleanup."""
    mocap_dir = mocap_dir or default_mocap_dir()
    if mocap_dir is None:
        raise FileNotFoundError("no mocap folder: pass --mocap-dir or set MOTION_ENVS_DATA")
    cache_dir = Path(cache_dir or default_cache_dir())
    cache_dir.mkdir(parents=True, exist_ok=True)
    sources = find_sources(Path(mocap_dir), subsets)
    if not sources:
        raise FileNotFoundError(f"no .bvh, .amc or .npz files under {mocap_dir}")
    report = BuildReport()
    body = BodyModel()
    for fps in fps_list:
        path = cache_dir / f"motion_{fps}fps_{content_hash(sources, fps, retarget_config, cleanup)[:16]}.npz"
        report.caches[fps] = path
        if path.exists():
            continue
        report.rebuilt = True
        parts = path.with_suffix(".parts")  # one file per finished clip: a killed build resumes from there
        parts.mkdir(exist_ok=True)
        clips: list[tuple[ClipSource, BodyMotion]] = []
        failures: list[str] = []
        for index, source in enumerate(tqdm(sources, desc=f"retarget @ {fps} fps", disable=not progress, unit="clip")):
            motion, failure = _clip_or_failure(parts / f"{index:05d}.pkl", source, fps, body, retarget_config, cleanup)
            if motion is not None:
                clips.append((source, motion))
            else:
                failures.append(f"{source.relative}: {failure}")
                tqdm.write(f"skipped {source.relative}: {failure}", file=sys.stderr)
        if not clips:
            raise RuntimeError(f"every clip under {mocap_dir} failed ({len(failures)}):\n  {_failure_summary(failures)}")
        _write_cache(path, clips, failures, fps, mocap_dir, cleanup)
        shutil.rmtree(parts)
        report.failures = failures
    report.clips = len(sources) - len(report.failures)
    return report


def _clip_or_failure(part: Path, source: ClipSource, fps: int, body: BodyModel, retarget_config: RetargetConfig,
                     cleanup: CleanupConfig | None) -> tuple[BodyMotion | None, str | None]:  # fmt: skip
    """One source's clip, or why it failed (one bad file must not abort the build: it is reported, the rest built).
    `part` keeps the outcome: a build killed later reads it back instead of loading the clip again (the part
    folder is named by the cache's content hash, so a part never outlives its sources, settings or code)."""
    if part.exists():
        with open(part, "rb") as file:
            return pickle.load(file)
    try:
        motion = load_clip(source, fps, body, retarget_config, cleanup)
        check_plausible(motion, source.relative)
        outcome = (motion, None)
    except Exception as error:
        known = isinstance(error, (MocapFormatError, UnknownSkeletonError, ValueError))
        outcome = (None, str(error) if known else f"{type(error).__name__}: {error}")
    atomic_write(part, lambda file: pickle.dump(outcome, file))
    return outcome


def _write_cache(path: Path, clips: list[tuple[ClipSource, BodyMotion]], failures: list[str], fps: int,
                 mocap_dir: Path, cleanup: CleanupConfig | None) -> None:  # fmt: skip
    motions = [motion for _, motion in clips]
    errors = [motion.info["retarget_error"] for motion in motions]
    shifts = [motion.info.get("cleanup_shift", np.zeros((motion.num_frames, 22))) for motion in motions]
    residuals = [motion.info.get("lock_residual", np.full((motion.num_frames, 4), np.nan)) for motion in motions]
    arrays = {
        "format": np.array(CACHE_FORMAT),
        "fps": np.array(fps),
        "transl": np.concatenate([m.transl for m in motions]).astype(np.float32),
        "global_orient": np.concatenate([m.global_orient for m in motions]).astype(np.float32),
        "body_pose": np.concatenate([m.body_pose for m in motions]).astype(np.float32),
        "clip_start": np.cumsum([0] + [m.num_frames for m in motions]),
        "clip_name": np.array([m.name for m in motions]),
        "clip_subject": np.array([m.subject for m in motions]),
        "clip_split": np.array([split_of(m.subject) for m in motions]),
        "clip_file": np.array([source.relative for source, _ in clips]),
        "clip_skeleton": np.array([m.info["skeleton"] for m in motions]),
        "retarget_error_mean": np.array([np.nanmean(e) for e in errors]),
        "retarget_error_p95": np.array([np.nanpercentile(e, 95) for e in errors]),
        "retarget_error_max": np.array([np.nanmax(e) for e in errors]),
        "contacts": np.concatenate([m.info["contacts"] for m in motions]),
        "contact_points": np.array(SOLE_POINTS),
        "cleanup": np.array(str(cleanup)),
        "cleanup_shift_mean": np.array([s.mean() for s in shifts]),
        "cleanup_shift_max": np.array([s.max() for s in shifts]),
        "pelvis_tilt_fix": np.array([motion.info.get("pelvis_tilt_fix", 0.0) for motion in motions]),
        "lock_residual_max": np.array([np.nanmax(r, initial=0.0) for r in residuals]),
        "failures": np.array(failures, dtype=str),
        "mocap_dir": np.array(str(mocap_dir)),
    }
    atomic_write(path, lambda file: np.savez_compressed(file, **arrays))
