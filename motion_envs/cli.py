"""The `motion-envs` command line: data, train, bench, play."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _data_build(args: argparse.Namespace) -> int:
    from motion_envs.data.build import build

    report = build(
        mocap_dir=args.mocap_dir,
        cache_dir=args.cache_dir,
        subsets=tuple(args.subset) if args.subset else None,
        fps_list=tuple(args.fps),
        progress=not args.quiet,
    )
    state = "built" if report.rebuilt else "up to date"
    for fps, path in report.caches.items():
        print(f"{fps} fps: {path} ({state})")
    print(f"{report.clips} clips, {len(report.failures)} skipped")
    for failure in report.failures:
        print(f"  skipped {failure}")
    return 0


def _data_start_poses(args: argparse.Namespace) -> int:
    from motion_envs.data.start_poses import write_start_poses

    path = write_start_poses(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=tuple(args.subset))
    print(f"wrote {path}")
    return 0


def _bench_data(args: argparse.Namespace) -> int:
    from benchmarks.data_quality import main as data_quality

    return data_quality(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=tuple(args.subset))


def _train(args: argparse.Namespace) -> int:
    if args.what != "gamma":
        return _not_yet(f"train {args.what}")(args)
    if args.stage != "predictor":
        return _not_yet(f"train gamma --stage {args.stage}")(args)
    from motion_envs.body import BodyModel
    from motion_envs.data.build import build
    from motion_envs.data.dataset import MotionDataset
    from motion_envs.data.primitives import GAMMA_FPS, MarkerClips
    from motion_envs.priors.gamma import MarkerCVAEConfig
    from motion_envs.priors.train_gamma import PredictorTrainConfig, train_predictor

    report = build(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=tuple(args.subset), fps_list=(GAMMA_FPS,))
    dataset = MotionDataset.load(report.caches[GAMMA_FPS])
    body = BodyModel()
    config = PredictorTrainConfig(
        model=MarkerCVAEConfig(seed_frames=args.seed_frames),
        epochs=args.epochs,
        rollout_epochs=args.rollout_epochs,
        batch_size=args.batch_size,
        window_stride=args.window_stride,
        run_dir=args.run_dir or Path(f"runs/gamma_predictor_{args.seed_frames}f"),
        weights=args.weights,
        data_hash=report.caches[GAMMA_FPS].stem,
        command="motion-envs " + " ".join(sys.argv[1:]),
    )
    entry = train_predictor(
        config, MarkerClips.from_dataset(dataset, "train", body, mirrored=True), MarkerClips.from_dataset(dataset, "validation", body)
    )
    for name, errors in entry["validation_marker_error_cm_per_frame"].items():
        print(f"validation marker error (cm) per frame, {name}: {json.dumps(errors)}")
    return 0


def _not_yet(what: str):
    def run(_: argparse.Namespace) -> int:
        print(f"motion-envs {what}: not available yet (it arrives with its environment)", file=sys.stderr)
        return 2

    return run


def _add_data_args(parser: argparse.ArgumentParser, default_subsets: list[str] | None) -> None:
    parser.add_argument("--mocap-dir", type=Path, default=None, help="mocap folder (default: $MOTION_ENVS_DATA or ../shared/mocap)")
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache folder (default: $MOTION_ENVS_CACHE or ~/.cache/motion_envs)")
    parser.add_argument("--subset", action="append", default=default_subsets,
                        help="only this subfolder of the mocap folder (repeatable)")  # fmt: skip


def parser() -> argparse.ArgumentParser:
    root = argparse.ArgumentParser(prog="motion-envs", description="Motion-prior Gymnasium environments.")
    commands = root.add_subparsers(dest="command", required=True, metavar="{data,train,bench,play}")

    data = commands.add_parser("data", help="build the motion cache from a mocap folder").add_subparsers(
        dest="action", required=True
    )
    build = data.add_parser("build", help="retarget every clip to the body and cache it (npz per fps)")
    _add_data_args(build, None)
    build.add_argument("--fps", type=int, nargs="+", default=[30, 40])
    build.add_argument("--quiet", action="store_true", help="no progress bar")
    build.set_defaults(run=_data_build)
    starts = data.add_parser("start-poses", help="write the shipped start poses from validation clips")
    _add_data_args(starts, ["cmu"])
    starts.set_defaults(run=_data_start_poses)

    train = commands.add_parser("train", help="train a prior or a policy (resumable: rerun the same command)")
    train.add_argument("what", help="gamma | wandr | clops | ppo | dqn (gamma's predictor so far)")
    train.add_argument("--stage", default="predictor", help="gamma: predictor | regressor | pose-vae")
    train.add_argument("--seed-frames", type=int, default=2, choices=(1, 2))
    train.add_argument("--epochs", type=int, default=30, help="single-primitive epochs")
    train.add_argument("--rollout-epochs", type=int, default=5, help="8-primitive rollout epochs after those")
    train.add_argument("--batch-size", type=int, default=128)
    train.add_argument("--window-stride", type=int, default=2, help="frames between training windows")
    train.add_argument("--run-dir", type=Path, default=None, help="checkpoints and tensorboard logs")
    train.add_argument("--weights", type=Path, default=None, help="output (default: priors/weights/)")
    _add_data_args(train, ["cmu"])
    train.set_defaults(run=_train)

    bench = commands.add_parser("bench", help="run a benchmark and write benchmarks/results/*.md").add_subparsers(
        dest="name", required=True
    )
    bench_data = bench.add_parser("data", help="data quality: clips, retarget error, foot skating, FK speed")
    _add_data_args(bench_data, ["cmu"])
    bench_data.set_defaults(run=_bench_data)

    play = commands.add_parser("play", help="watch a policy or prior in an environment")
    play.add_argument("env_id", nargs="?")
    play.set_defaults(run=_not_yet("play"))
    return root


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    return int(args.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
