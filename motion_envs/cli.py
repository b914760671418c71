"""The `motion-envs` command line: data, train, bench, play."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from motion_envs.allocator import keep_freed_memory
from motion_envs.data.paths import SHIPPED_SUBSETS

THROUGHPUT_OUTPUT_HELP = ("results file stem under benchmarks/results/ (default throughput, the main table; e.g. "
                          "throughput_avx2 for a CPU of another class)")  # fmt: skip


def _data_build(args: argparse.Namespace) -> int:
    from motion_envs.data.build import build
    from motion_envs.data.cleanup import CleanupConfig

    report = build(
        mocap_dir=args.mocap_dir,
        cache_dir=args.cache_dir,
        subsets=_subsets(args),
        fps_list=tuple(args.fps),
        progress=not args.quiet,
        cleanup=None if args.no_cleanup else CleanupConfig(),
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

    path = write_start_poses(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=_subsets(args))
    print(f"wrote {path}")
    return 0


def _bench_data(args: argparse.Namespace) -> int:
    from benchmarks.data_quality import main as data_quality

    return data_quality(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=_subsets(args), timing=not args.no_timing)


def _bench_gamma(args: argparse.Namespace) -> int:
    from benchmarks.gamma_control import main as gamma_control

    return gamma_control(pairs=args.pairs, clones=args.clones, seed=args.seed, quick=args.quick, bf16=args.bf16,
                         precision=args.precision, output=args.output, ray_address=args.ray, policies=args.policies,
                         weights_dir=args.weights_dir, mirror_right_goals=args.mirror_right_goals)  # fmt: skip


def _bench_clops(args: argparse.Namespace) -> int:
    from benchmarks.clops_matrix import main as clops_matrix
    from motion_envs.scenes.layouts import FAMILIES

    families = tuple(args.families.split(",")) if args.families else tuple(FAMILIES)
    unknown = set(families) - set(FAMILIES)
    if unknown:
        print(f"unknown families {sorted(unknown)}; choose from {', '.join(FAMILIES)}", file=sys.stderr)
        return 2
    return clops_matrix(episodes_per_family=args.episodes, families=families, seed=args.seed, ray_address=args.ray)


def _add_ray_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                        help="fan the episodes out over Ray tasks (pip install -e '.[ray]'): a local Ray, or the cluster "
                             "at ADDRESS (auto, host:6379, ray://host:10001); same table as without")  # fmt: skip


def _bench_wander(args: argparse.Namespace) -> int:
    from benchmarks.gamma_wander import main as gamma_wander

    return gamma_wander(paths=args.paths, rooms=args.rooms, seed=args.seed, quick=args.quick, policies=args.policies,
                        output=args.output)  # fmt: skip


def _bench_wandr(args: argparse.Namespace) -> int:
    from benchmarks.wandr_grid import main as wandr_grid

    return wandr_grid(quick=args.quick, seed=args.seed, data_fs=not args.no_data_fs, optimisation=not args.no_optimisation,
                      variants_dir=args.variants_dir, only=args.only, ray_address=args.ray, timing=not args.no_timing)  # fmt: skip


def _bench_wandr_pace(args: argparse.Namespace) -> int:
    from benchmarks.wandr_pace import main as wandr_pace
    from motion_envs.priors.training import WEIGHTS_DIR

    return wandr_pace(args.weights or [WEIGHTS_DIR / "wandr.pt"])


def _bench_clops_actions(args: argparse.Namespace) -> int:
    from benchmarks.clops_actions import main as clops_actions
    from motion_envs.priors.training import WEIGHTS_DIR

    return clops_actions(args.weights or [WEIGHTS_DIR / "clops.pt", WEIGHTS_DIR / "clean" / "clops.pt"], rooms=args.rooms)


def _bench_cleanup_video(args: argparse.Namespace) -> int:
    from benchmarks.cleanup_video import main as cleanup_video

    return cleanup_video(clip=args.clip, mocap_dir=args.mocap_dir, cache_dir=args.cache_dir)


def _bench_floor(args: argparse.Namespace) -> int:
    from benchmarks.floor import main as floor

    return floor(steps=args.steps, seed=args.seed, weights_dir=args.weights_dir, output=args.output or "floor")


def _bench_gamma_turns(args: argparse.Namespace) -> int:
    from benchmarks.gamma_turns import main as gamma_turns

    return gamma_turns(bodies=args.bodies, seed=args.seed)


def _bench_speed(args: argparse.Namespace) -> int:
    from benchmarks.throughput import main as throughput

    return throughput(output=args.output)


def _bench_rllib(args: argparse.Namespace) -> int:
    from benchmarks.rllib_speed import main as rllib_speed

    return rllib_speed(bodies=args.bodies, curve_from=args.curve_from)


def _bench_ray_scaling(args: argparse.Namespace) -> int:
    from benchmarks.ray_scaling import main as ray_scaling

    return ray_scaling()


def _bench_gpu(args: argparse.Namespace) -> int:
    from benchmarks.gpu_check import main as gpu_check

    return gpu_check()


def _bench_render(args: argparse.Namespace) -> int:
    from benchmarks.render_speed import main as render_speed

    return render_speed(output=args.output)


def _bench_gamma_feet(args: argparse.Namespace) -> int:
    from benchmarks.gamma_feet import main as gamma_feet

    return gamma_feet(bodies=args.bodies, primitives=args.primitives, seed=args.seed)


def _bench_gamma_realism(args: argparse.Namespace) -> int:
    from benchmarks.gamma_realism import main as gamma_realism

    return gamma_realism(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=_subsets(args),
                         rollouts=args.rollouts, primitives=args.primitives, seed=args.seed, weights_dir=args.weights_dir,
                         output=args.output or "gamma_realism")  # fmt: skip


def _play(args: argparse.Namespace) -> int:
    from motion_envs.play import play

    env_kwargs = _env_options(args)
    for summary in play(args.env_id, args.policy, args.baseline, args.video, args.seed, args.episodes, args.every, args.search,
                        args.save_rollout, **env_kwargs):  # fmt: skip
        print(" ".join(f"{name}={value}" for name, value in summary.items()))
    if args.video:
        print(f"video: {args.video}")
    if args.save_rollout:
        print(f"rollout: {args.save_rollout} (motion-envs view {args.save_rollout})")
    return 0


def _ship(args: argparse.Namespace) -> int:
    from motion_envs.priors.training import ship_trained

    contents, notes = None, {}
    if args.drop_env_option:
        from agents.policy_files import without_env_options

        contents = without_env_options(args.file, args.drop_env_option)
        notes["promoted"] = (f"trained as {args.file} with the env option(s) {', '.join(args.drop_env_option)} (its record's "
                             "config); shipped without them in the file's trained_for")  # fmt: skip
    if args.file.suffix == ".zip":
        _refuse_run_folder_options(args.file, dropped=args.drop_env_option or [])
    if args.note:
        notes["note"] = args.note
    ship_trained(args.file, name=args.name, contents=contents, notes=notes)
    return 0


def _refuse_run_folder_options(policy: Path, dropped: list[str]) -> None:
    """Refuse to ship a policy whose saved env options, but for those `dropped`, name weights outside the package (a
    prior from a run folder): users would not have them."""
    from agents.policy_files import read_policy_file

    trained_for = read_policy_file(policy).trained_for
    options = {key: value for key, value in (trained_for.env_kwargs if trained_for else {}).items()
               if key in ("weights", "weights_dir") and value is not None and key not in dropped}  # fmt: skip
    if options:
        raise ValueError(f"{policy} was trained with env option(s) {options}, which users of the package would not have: "
                         "ship that prior first, then ship the policy with --drop-env-option " + " --drop-env-option ".join(options))  # fmt: skip


def _view(args: argparse.Namespace) -> int:
    from motion_envs.play import LiveEpisodes
    from motion_envs.rollout import Rollout
    from motion_envs.viewer import RolloutViewer

    if (args.rollout is None) == (args.env is None):
        print("motion-envs view: give a rollout file or --env (live), not both", file=sys.stderr)
        return 2
    env_kwargs = _env_options(args)
    live = LiveEpisodes(args.env, args.policy, args.baseline, args.seed, env_kwargs) if args.env else None
    rollout = Rollout.load(args.rollout) if args.rollout else live.more()
    scene = _scene_argument(args.scene or rollout.scene or None, args.scene_file)  # a ClopsNav rollout names its room
    viewer = RolloutViewer(rollout, scene, host=args.host, port=args.port, extend=None if live is None else live.more)
    print(f"viewer on {viewer.url} (Ctrl-C to stop)", flush=True)
    try:
        viewer.run(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        viewer.stop()
    return 0


def _populate(args: argparse.Namespace) -> int:
    import torch

    from agents.controllers import PolicyLatent
    from motion_envs.populate import populate, write_video
    from motion_envs.priors.training import WEIGHTS_DIR
    from motion_envs.wrappers.tree_search import SearchSettings

    scene = _scene_argument(args.scene, args.scene_file)
    if scene is None:
        print("motion-envs populate: give a room (--scene living:1003) or a scene file (--scene-file)", file=sys.stderr)
        return 2
    proposal = PolicyLatent(args.policy or WEIGHTS_DIR / "ppo_gammawander_alpha1_paper.zip", seed=args.seed)
    search = None if args.no_search else SearchSettings(roots=args.roots, children=4, keep=2, max_depth=args.horizon)
    if args.threads:
        torch.set_num_threads(args.threads)
    result = populate(scene, proposal, args.bodies, args.seconds, args.seed, search, scene_spec=args.scene or "")
    print(f"{result.bodies} bodies, {result.motion_seconds:.1f} s of motion in {result.wall_seconds:.1f} s "
          f"({result.realtime_factor:.2f}x real time): {result.arrivals} arrivals ({result.arrivals_per_minute:.1f}/min), "
          f"collisions {100 * result.collided:.1f}% of body-primitives, overlapping another body {100 * result.overlapping:.1f}%")
    if args.save_rollout:
        result.rollout.save(args.save_rollout)
        scene_hint = f" --scene {args.scene}" if args.scene else f" --scene-file {args.scene_file}"
        print(f"rollout: {args.save_rollout} (motion-envs view {args.save_rollout}{'' if args.scene else scene_hint})")
    if args.video:
        print(f"video: {write_video(result, scene, args.video)}")
    return 0


def _scene_argument(spec: str | None, path: Path | None):
    """A scene from 'family:seed' or a file (None when neither is given)."""
    from motion_envs.scenes import load_scene, make_scene

    if path is not None:
        return load_scene(path)
    if spec is None:
        return None
    family, _, seed = spec.partition(":")
    return make_scene(family, int(seed or 0))


def _train_ppo(args: argparse.Namespace) -> int:
    from agents.train_ppo import PPOTrainConfig, train_ppo

    given = {"env_id": args.env, "reward": args.reward, "alpha": args.alpha, "num_envs": args.num_envs,
             "total_timesteps": args.timesteps, "run_dir": args.run_dir, "weights": args.weights, "seed": args.seed,
             "init": args.init, "log_std_init": args.log_std_init, "learning_rate": args.learning_rate,
             "n_steps": args.n_steps, "anchor": args.anchor, "kl_mean": args.kl_mean, "ship": args.ship or None, "device": args.device,
             "env_kwargs": _env_options(args) or None, "engine": args.engine, "env_runners": args.env_runners,
             "address": args.address, "cpus_per_env_runner": args.cpus_per_env_runner, "keep": args.keep}  # fmt: skip
    config = PPOTrainConfig(command="motion-envs " + " ".join(sys.argv[1:]),
                            **{name: value for name, value in given.items() if value is not None})  # fmt: skip
    if config.run_dir == PPOTrainConfig.run_dir:
        config.run_dir = Path(f"runs/{config.weights_path().stem}" + ("_rllib" if config.engine == "rllib" else ""))
    clone_from = None
    if config.init == "data" and not config.checkpoint_path().exists():
        if "GammaReach" not in config.env_id:
            print(f"--init data clones GAMMA latents; use --init scratch for {config.env_id}", file=sys.stderr)
            return 2
        from motion_envs.data.goal_windows import goal_windows

        clone_from = goal_windows(_marker_clips(_gamma_dataset(args), "train", mirrored=True))
    entry = train_ppo(config, clone_from)
    last = entry["curve"][-1] if entry["curve"] else {}
    print(f"{entry['timesteps']} steps; latest success rate {last.get('success_rate', float('nan')):.2f}; "
          f"weights {config.weights_path()}")
    return 0


def _train_dqn(args: argparse.Namespace) -> int:
    from agents.train_dqn import DQNTrainConfig, train_dqn

    given = {"family": args.family, "known_goal": args.known_goal or None, "goal_memory": args.goal_memory or None,
             "num_envs": args.num_envs, "total_timesteps": args.timesteps, "run_dir": args.run_dir, "weights": args.weights, "seed": args.seed,
             "learning_rate": args.learning_rate, "batch_size": args.batch_size, "ship": args.ship or None, "device": args.device,
             "env_kwargs": _env_options(args) or None, "engine": args.engine, "env_runners": args.env_runners,
             "address": args.address, "init": None if args.init is None else Path(args.init)}  # fmt: skip
    config = DQNTrainConfig(command="motion-envs " + " ".join(sys.argv[1:]),
                            **{name: value for name, value in given.items() if value is not None})  # fmt: skip
    if config.run_dir == DQNTrainConfig.run_dir:
        config.run_dir = Path(f"runs/{config.weights_path().stem}" + ("_rllib" if config.engine == "rllib" else ""))
    entry = train_dqn(config)
    last = entry["curve"][-1] if entry["curve"] else {}
    print(f"{entry['timesteps']} steps; latest success rate {last.get('success_rate', float('nan')):.2f}; "
          f"weights {config.weights_path()}")
    return 0


def _env_options(args: argparse.Namespace) -> dict[str, object]:
    """The command's repeated `--env-option key=value` as gym.make keyword arguments."""
    return dict(_env_option(option) for option in args.env_option)


def _env_option(option: str) -> tuple[str, object]:
    """'key=value' -> (key, value as JSON if it parses, else the string)."""
    key, equals, value = option.partition("=")
    if not equals or not key:
        raise SystemExit(f"--env-option must look like key=value, got {option!r}")
    try:
        return key, json.loads(value)
    except json.JSONDecodeError:
        return key, value


def _train_priors(args: argparse.Namespace) -> int:
    from motion_envs.priors.recipe import train_priors

    passed_args = [*(["--mocap-dir", str(args.mocap_dir)] if args.mocap_dir else []),
                   *(["--cache-dir", str(args.cache_dir)] if args.cache_dir else []),
                   *[word for name in (args.subset or []) for word in ("--subset", name)],
                   *(["--threads", str(args.threads)] if args.threads else [])]  # fmt: skip
    stages = args.stages.split(",") if args.stages else None
    return train_priors(stages, Path(args.run_dir or "runs/priors"), args.ship, passed_args)


def _train(args: argparse.Namespace) -> int:
    if args.threads is not None:
        if args.threads < 1:
            raise ValueError(f"--threads must be at least 1, got {args.threads}")
        import torch

        torch.set_num_threads(args.threads)
    if args.what == "priors":
        return _train_priors(args)
    if args.what == "ppo":
        return _train_ppo(args)
    if args.what == "wandr":
        return _train_wandr(args)
    if args.what == "clops":
        return _train_clops(args)
    if args.what == "dqn":
        return _train_dqn(args)
    stages = {"predictor": _train_gamma_predictor, "regressor": _train_gamma_regressor, "pose-vae": _train_gamma_pose_vae,
              "g-cvae": _train_gamma_g_cvae, "heading": _train_gamma_heading}  # fmt: skip
    if args.stage not in stages:
        print(f"unknown --stage {args.stage!r}; choose from {', '.join(stages)}", file=sys.stderr)
        return 2
    dataset = _gamma_dataset(args)
    given = {"epochs": args.epochs, "batch_size": args.batch_size, "run_dir": args.run_dir, "weights": args.weights,
             "window_stride": args.window_stride, "rollout_epochs": args.rollout_epochs, "ship": args.ship or None,
             "contact_weight": args.contact_weight}  # fmt: skip
    common = {"data_hash": dataset.path.stem, "command": "motion-envs " + " ".join(sys.argv[1:]),
              **{name: value for name, value in given.items() if value is not None}}  # fmt: skip
    entry = stages[args.stage](args, dataset, common)
    for name, value in entry.items():
        if name.startswith("validation"):
            print(f"{name}: {json.dumps(value)}")
    return 0


def _delta_prior_clips(args: argparse.Namespace):
    """The 30 fps dataset of `--subset` (cache built from the mocap folder if missing) and its training clips
    (mirrored too) and validation clips, as WANDR's and CLOPS's priors train on them."""
    from motion_envs.body import BodyModel
    from motion_envs.data.build import build
    from motion_envs.data.dataset import MotionDataset
    from motion_envs.priors.train_wandr import WandrClips
    from motion_envs.priors.wandr_features import FPS

    dataset = MotionDataset.load(build(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=_subsets(args),
                                       fps_list=(FPS,)).caches[FPS])  # fmt: skip
    body = BodyModel()
    return dataset, WandrClips.from_dataset(dataset, "train", body, mirrored=True), WandrClips.from_dataset(dataset, "validation", body)


def _train_wandr(args: argparse.Namespace) -> int:
    from motion_envs.priors.train_wandr import WandrTrainConfig, default_weights, train_wandr
    from motion_envs.priors.training import weights_destination
    from motion_envs.priors.wandr import WandrConfig

    subsets = _subsets(args)  # `--subset hdm05` adds to the default SHIPPED_SUBSETS
    dataset, train_clips, validation_clips = _delta_prior_clips(args)
    intentions = tuple(args.intentions.split(",")) if args.intentions else WandrConfig().intentions
    model = WandrConfig(intentions=intentions, learned_prior=args.learned_prior, **({"layers": args.layers} if args.layers else {}))
    name = default_weights(model, subsets)
    run_dir = args.run_dir or Path("runs") / Path(name).stem
    given = {"epochs": args.epochs, "batch_size": args.batch_size, "window_stride": args.window_stride,
             "seed": args.seed, "max_rollout": args.max_rollout, "kl_weight": args.kl_weight,
             "late_kl_weight": args.late_kl_weight, "kl_raise_epoch": args.kl_raise_epoch,
             "weights": weights_destination(name, run_dir, args.weights, args.ship), "run_dir": run_dir, "init": _prior_init(args),
             "far_goal_probability": args.far_goal_probability, "contact_weight": args.contact_weight,
             "pace_weight": args.pace_weight, "upright_weight": args.upright_weight, "turn_weight": args.turn_weight,
             "pace_frames": args.pace_frames, "learning_rate": args.learning_rate, "reach_weight": args.reach_weight,
             "end_goal_probability": args.end_goal_probability}  # fmt: skip
    config = WandrTrainConfig(model=model, data_hash=dataset.path.stem, command="motion-envs " + " ".join(sys.argv[1:]),
                              **{key: value for key, value in given.items() if value is not None})  # fmt: skip
    entry = train_wandr(config, train_clips, validation_clips)
    for key, value in entry.items():
        if key.startswith("validation"):
            print(f"{key}: {json.dumps(value)}")
    print(f"weights {config.weights}")
    return 0


def _prior_init(args: argparse.Namespace) -> Path | None:
    """--prior-init as a path (None for 'scratch' or when not given)."""
    return None if args.prior_init in (None, "scratch") else Path(args.prior_init)


def _train_clops(args: argparse.Namespace) -> int:
    from motion_envs.priors.clops import ClopsConfig
    from motion_envs.priors.train_clops import ClopsTrainConfig, train_clops
    from motion_envs.priors.training import WEIGHTS_DIR

    dataset, train_clips, validation_clips = _delta_prior_clips(args)
    model = ClopsConfig(**{name: value for name, value in (("layers", args.layers), ("actions", args.actions)) if value})
    given = {"epochs": args.epochs, "batch_size": args.batch_size, "window_stride": args.window_stride, "seed": args.seed,
             "max_rollout": args.max_rollout, "kl_weight": args.kl_weight, "weights": args.weights, "run_dir": args.run_dir,
             "ship": args.ship or None, "contact_weight": args.contact_weight, "pace_weight": args.pace_weight,
             "upright_weight": args.upright_weight, "turn_weight": args.turn_weight, "pace_frames": args.pace_frames,
             "learning_rate": args.learning_rate}  # fmt: skip
    if args.prior_init is not None:
        given["init"] = _prior_init(args)
    if args.actions_from is not None:
        given["actions_from"] = WEIGHTS_DIR / "clops.pt" if args.actions_from == "shipped" else Path(args.actions_from)
    config = ClopsTrainConfig(model=model, data_hash=dataset.path.stem, command="motion-envs " + " ".join(sys.argv[1:]),
                              **{key: value for key, value in given.items() if value is not None or key == "init"})  # fmt: skip
    entry = train_clops(config, train_clips, validation_clips)
    for key, value in entry.items():
        if key.startswith("validation"):
            print(f"{key}: {json.dumps(value)}")
    print(f"weights {config.output('clops.pt')}")
    return 0


def _gamma_dataset(args: argparse.Namespace):
    """The 40 fps motion cache (built from the mocap folder if it is missing)."""
    from motion_envs.data.build import build
    from motion_envs.data.dataset import MotionDataset
    from motion_envs.data.primitives import GAMMA_FPS

    report = build(mocap_dir=args.mocap_dir, cache_dir=args.cache_dir, subsets=_subsets(args), fps_list=(GAMMA_FPS,))
    return MotionDataset.load(report.caches[GAMMA_FPS])


def _train_config(config_type: type, common: dict, **extra):
    """`config_type` from the command's options that it has (others belong to other stages)."""
    from dataclasses import fields

    names = {field.name for field in fields(config_type)}
    return config_type(**{name: value for name, value in common.items() if name in names}, **extra)


def _marker_clips(dataset, split: str, mirrored: bool = False):
    from motion_envs.body import BodyModel
    from motion_envs.data.primitives import MarkerClips

    return MarkerClips.from_dataset(dataset, split, BodyModel(), mirrored=mirrored)


def _train_gamma_predictor(args: argparse.Namespace, dataset, common: dict) -> dict:
    from motion_envs.priors.gamma import MarkerCVAEConfig
    from motion_envs.priors.train_gamma import PredictorTrainConfig, train_predictor

    common.setdefault("run_dir", Path(f"runs/gamma_predictor_{args.seed_frames}f"))
    config = _train_config(PredictorTrainConfig, common, model=MarkerCVAEConfig(seed_frames=args.seed_frames))
    return train_predictor(config, _marker_clips(dataset, "train", mirrored=True), _marker_clips(dataset, "validation"))


def _train_gamma_regressor(args: argparse.Namespace, dataset, common: dict) -> dict:
    from motion_envs.priors.train_regressor import RegressorTrainConfig, train_regressor

    config = _train_config(RegressorTrainConfig, common)
    return train_regressor(config, _marker_clips(dataset, "train", mirrored=True), _marker_clips(dataset, "validation"))


def _train_gamma_g_cvae(args: argparse.Namespace, dataset, common: dict) -> dict:
    from baselines.g_cvae import GoalCVAETrainConfig, train_goal_cvae
    from motion_envs.data.goal_windows import goal_windows

    def windows(split: str, mirrored: bool):
        return goal_windows(_marker_clips(dataset, split, mirrored=mirrored))

    return train_goal_cvae(_train_config(GoalCVAETrainConfig, common), windows("train", True), windows("validation", False))


def _train_gamma_heading(args: argparse.Namespace, dataset, common: dict) -> dict:
    """Measure the heading calibration of the predictors with the regressor (`motion_envs.priors.gamma_heading`)
    on the training windows and write it (run folder, `--weights`, or beside the shipped weights with --ship)."""
    from motion_envs.body import BodyModel
    from motion_envs.priors.gamma_heading import CALIBRATION_FILE, CALIBRATION_KIND, measure_heading_calibration, network_fingerprints
    from motion_envs.priors.train_gamma import load_predictor
    from motion_envs.priors.train_regressor import load_regressor
    from motion_envs.priors.training import WEIGHTS_DIR, ship, weights_destination

    stride = args.window_stride or 4
    paths = {name: getattr(args, name) or WEIGHTS_DIR / f"gamma_{name}.pt" for name in ("predictor_1f", "predictor_2f", "regressor")}
    networks = {name: (load_regressor if name == "regressor" else load_predictor)(path) for name, path in paths.items()}
    predictors = {name: networks[name] for name in ("predictor_1f", "predictor_2f")}
    calibration, figures = measure_heading_calibration(predictors, networks["regressor"], BodyModel(),
                                                       _marker_clips(dataset, "train", mirrored=True), stride)  # fmt: skip
    entry = {"kind": CALIBRATION_KIND, "config": {}, "data_hash": common["data_hash"], "command": common["command"],
             "window_stride": stride, "measured_with": {name: str(getattr(args, name) or f"shipped {path.name}") for name, path in paths.items()},
             "fingerprints": network_fingerprints(networks), "validation_heading": figures}  # fmt: skip
    weights = weights_destination(CALIBRATION_FILE, Path(args.run_dir or "runs/gamma_heading"), args.weights, args.ship)
    return ship(calibration, weights, entry)


def _train_gamma_pose_vae(args: argparse.Namespace, dataset, common: dict) -> dict:
    import numpy as np
    import torch

    from motion_envs.priors.train_pose_prior import PoseVAETrainConfig, train_pose_vae

    def poses(split: str, mirrored: bool) -> torch.Tensor:
        clips = dataset.clips(split, mirrored=mirrored)
        return torch.as_tensor(np.concatenate([clip.body_pose for clip in clips]), dtype=torch.float32)

    return train_pose_vae(_train_config(PoseVAETrainConfig, common), poses("train", True), poses("validation", False))


def _add_data_args(parser: argparse.ArgumentParser, default_subsets: list[str] | None) -> None:
    parser.add_argument("--mocap-dir", type=Path, default=None,
                        help="the folder holding the clips, any layout (default: $MOTION_ENVS_DATA or ../shared/mocap)")  # fmt: skip
    parser.add_argument("--cache-dir", type=Path, default=None, help="cache folder (default: $MOTION_ENVS_CACHE or ~/.cache/motion_envs)")
    default = f" (default: {', '.join(default_subsets)} where the folder has it, else all of it)" if default_subsets else " (default: all of it)"
    parser.add_argument("--subset", action="append", default=None,
                        help="also read this subfolder of the mocap folder (repeatable)" + default)  # fmt: skip
    parser.set_defaults(default_subsets=default_subsets or [])


def _subsets(args: argparse.Namespace) -> tuple[str, ...]:
    """The mocap subfolders a command reads: its default subfolders (`SHIPPED_SUBSETS`) that the mocap folder has, then every
    `--subset`; empty: the whole folder. `--mocap-dir` so means one thing for every command, the folder holding the
    clips, with or without a cmu/ subfolder."""
    from motion_envs.data.paths import default_mocap_dir

    folder = args.mocap_dir or default_mocap_dir()
    present = [name for name in args.default_subsets if folder is not None and (Path(folder) / name).is_dir()]
    return tuple(dict.fromkeys([*present, *(args.subset or [])]))


def parser() -> argparse.ArgumentParser:
    root = argparse.ArgumentParser(prog="motion-envs", description="Motion-prior Gymnasium environments.",
                                   epilog="--debug (anywhere): show the traceback of an error instead of one line")  # fmt: skip
    commands = root.add_subparsers(dest="command", required=True, metavar="{data,train,bench,play,populate,view,ship}")

    data = commands.add_parser("data", help="build the motion cache from a mocap folder").add_subparsers(
        dest="action", required=True
    )
    build = data.add_parser("build", help="retarget every clip to the body and cache it (npz per fps)")
    _add_data_args(build, list(SHIPPED_SUBSETS))  # the clips `train` and `bench` read, so their cache is this one
    build.add_argument("--fps", type=int, nargs="+", default=[30, 40])
    build.add_argument("--quiet", action="store_true", help="no progress bar")
    build.add_argument("--no-cleanup", action="store_true",
                       help="skip foot contacts, floor levelling and foot locking (to compare; its own cache)")  # fmt: skip
    build.set_defaults(run=_data_build)
    starts = data.add_parser("start-poses", help="write the shipped start poses from validation clips")
    _add_data_args(starts, list(SHIPPED_SUBSETS))
    starts.set_defaults(run=_data_start_poses)

    train = commands.add_parser("train", help="train a prior or a policy (resumable: rerun the same command)")
    train.add_argument("what", choices=("gamma", "ppo", "wandr", "clops", "dqn", "priors"),
                       help="what to train; priors: every shipped prior with its recipe (motion_envs/priors/recipe.py)")
    train.add_argument("--stages", default=None,
                       help="priors: comma-separated stages to run (default all; e.g. "
                            "wandr_short,wandr_60,wandr,clops_stage1,clops_stage2,clops)")
    train.add_argument("--stage", default="predictor",
                       help="gamma: predictor | regressor | pose-vae | g-cvae | heading (the predictors' heading "
                            "calibration, measured on the training windows; motion_envs/priors/gamma_heading.py)")  # fmt: skip
    for network in ("predictor-1f", "predictor-2f", "regressor"):
        train.add_argument(f"--{network}", type=Path, default=None,
                           help=f"gamma heading: the {network.replace('-', ' ')} weights to calibrate (default: the shipped ones)")  # fmt: skip
    train.add_argument("--seed-frames", type=int, default=2, choices=(1, 2), help="predictor: seed frames")
    train.add_argument("--epochs", type=int, default=None, help="epochs (predictor: single-primitive epochs)")
    train.add_argument("--rollout-epochs", type=int, default=None, help="predictor: 8-primitive rollout epochs after those")
    train.add_argument("--batch-size", type=int, default=None, help="default: the stage's own")
    train.add_argument("--window-stride", type=int, default=None, help="frames between training windows")
    train.add_argument("--run-dir", type=Path, default=None, help="checkpoints and tensorboard logs")
    train.add_argument("--weights", type=Path, default=None, help="output file (default: the run folder, or priors/weights/ with --ship)")
    train.add_argument("--ship", action="store_true",
                       help="write the weights into the package (motion_envs/priors/weights/ + manifest.json), replacing the shipped ones")
    train.add_argument("--env", default=None, help="ppo: environment id (default motion_envs/GammaReach-v0)")
    train.add_argument("--reward", default=None,
                       help="ppo: reward config (GammaReach: paper (default) | release | paper:goal=5; WandrReach: default)")
    train.add_argument("--alpha", type=float, default=None, help="ppo: weight of the KL-to-prior regulariser (paper: 1, 10)")
    train.add_argument("--num-envs", type=int, default=None, help="ppo, dqn: bodies stepped together")
    train.add_argument("--timesteps", type=int, default=None, help="ppo, dqn: total env steps (primitives; dqn: actions)")
    train.add_argument("--init", default=None,
                       help="ppo: start the actor from the data's latents ('data', default), from 'scratch', or from a policy .zip; "
                            "dqn: fine-tune a policy .zip (default: a new Q-network)")
    train.add_argument("--log-std-init", type=float, default=None, help="ppo: initial log sigma of the policy (default -1)")
    train.add_argument("--learning-rate", type=float, default=None, help="ppo, dqn, wandr, clops: Adam learning rate")
    train.add_argument("--n-steps", type=int, default=None, help="ppo: primitives per body per rollout")
    train.add_argument("--anchor", type=float, default=None, help="ppo: weight of KL to the cloned policy (default 0)")
    train.add_argument("--kl-mean", choices=("zero", "cloned"), default=None,
                       help="ppo: centre of the alpha-weighted KL: zero (the paper's N(0, I), default) or cloned "
                            "(N(cloned policy's mean, I), ours; needs --init data or a policy trained with it)")  # fmt: skip
    train.add_argument("--keep", choices=("best", "last"), default=None,
                       help="ppo: ship the checkpoint of the best success window (default) or the last one")
    train.add_argument("--env-option", action="append", default=[], metavar="KEY=VALUE",
                       help="ppo, dqn: a further gym.make argument of the env, e.g. frames_per_step=2 (repeatable)")
    train.add_argument("--intentions", default=None,
                       help="wandr: intention components, comma-separated (default wrist,pelvis,orientation)")
    train.add_argument("--layers", type=int, default=None, help="wandr: Linear layers of encoder and decoder (default 8)")
    train.add_argument("--max-rollout", type=int, default=None, help="wandr: longest training rollout in frames (default 10)")
    train.add_argument("--kl-weight", type=float, default=None, help="wandr: β of the KL term (paper 0.01)")
    train.add_argument("--late-kl-weight", type=float, default=None, help="wandr: β from --kl-raise-epoch on")
    train.add_argument("--kl-raise-epoch", type=int, default=None, help="wandr: first epoch of --late-kl-weight")
    train.add_argument("--family", default=None, help="dqn: ClopsNav scene family trained on (default open; mixed: all five)")
    train.add_argument("--known-goal", action="store_true", help="dqn: also observe the goal position (CLOPS + known goal)")
    train.add_argument("--goal-memory", action="store_true",
                       help="dqn: also observe a memory of what the view has shown (where the goal was last seen; ours)")
    train.add_argument("--actions", type=int, default=None, help="clops: k-means head-delta clusters K (default 16)")
    train.add_argument("--actions-from", default=None, metavar="CLOPS.pt|shipped",
                       help="clops: keep this prior's action deltas ('shipped': the shipped prior's) instead of a k-means fit")
    train.add_argument("--learned-prior", action="store_true",
                       help="wandr: a conditional prior p(z | c) instead of N(0, I) (ours; samplers still draw N(0, I) noise)")
    train.add_argument("--far-goal-probability", type=float, default=None,
                       help="wandr: share of training goals drawn ≥ 1.5 m away (default 0.5; the release: 1)")
    train.add_argument("--prior-init", "--clops-init", dest="prior_init", default=None,
                       help="wandr, clops: prior weights to start from, or 'scratch' (default: wandr scratch, clops the shipped wandr.pt)")
    train.add_argument("--contact-weight", type=float, default=None,
                       help="gamma predictor, wandr, clops: weight of the contact loss (stance feet held still where the "
                            "cleaned data labels contact; default 0 (off) for gamma, 1 for wandr/clops)")  # fmt: skip
    train.add_argument("--pace-weight", type=float, default=None,
                       help="wandr, clops: weight of the pace term (z ~ N(0, I) rollouts pulled to the data's progress "
                            "towards the goal; default 0, off)")  # fmt: skip
    train.add_argument("--upright-weight", type=float, default=None,
                       help="wandr, clops: weight of the upright term (the same rollouts' head height above the feet pulled "
                            "to the data's; default 0, off)")  # fmt: skip
    train.add_argument("--turn-weight", type=float, default=None,
                       help="wandr, clops: weight of the turn term (the same rollouts' heading gap to the goal frame's "
                            "pulled to the data's; default 0, off)")  # fmt: skip
    train.add_argument("--pace-frames", type=int, default=None,
                       help="wandr, clops: frames of each pace / upright rollout (default 90)")
    train.add_argument("--reach-weight", type=float, default=None,
                       help="wandr: weight of the reach term (the same rollouts' right-wrist distance to the goal pulled "
                            "to the data's; default 0, off)")  # fmt: skip
    train.add_argument("--end-goal-probability", type=float, default=None,
                       help="wandr: share of those rollouts whose goal is due at their last frame, as the paper's "
                            "protocol (default 0)")  # fmt: skip
    train.add_argument("--device", default=None, help="ppo, dqn: where the policy and the prior run (default cpu; cuda)")
    train.add_argument("--engine", default=None, choices=("sb3", "rllib"),
                       help="ppo, dqn: Stable-Baselines3 in this process (default) or RLlib on Ray (pip install -e '.[ray]')")
    train.add_argument("--env-runners", type=int, default=None,
                       help="--engine rllib: Ray env-runner actors sharing --num-envs bodies (default 0: the driver samples)")
    train.add_argument("--cpus-per-env-runner", type=int, default=None,
                       help="ppo --engine rllib: CPUs (torch threads) per env runner (default 1)")
    train.add_argument("--address", default=None,
                       help="--engine rllib: the Ray cluster to join (e.g. auto, host:6379); default a local Ray")
    train.add_argument("--seed", type=int, default=None)
    train.add_argument("--threads", type=int, default=None,
                       help="torch threads (default: torch's, one per core); 1 runs two trainings side by side on 2 cores")
    _add_data_args(train, list(SHIPPED_SUBSETS))
    train.set_defaults(run=_train)

    bench = commands.add_parser("bench", help="run a benchmark and write benchmarks/results/*.md").add_subparsers(
        dest="name", required=True
    )
    bench_data = bench.add_parser("data", help="data quality: clips, retarget error, foot skating, FK speed")
    _add_data_args(bench_data, list(SHIPPED_SUBSETS))
    bench_data.add_argument("--no-timing", action="store_true", help="leave out the reader and FK speed sections (busy machine)")
    bench_data.set_defaults(run=_bench_data)
    bench_gamma = bench.add_parser("gamma", help="GAMMA goal reaching (Table 1 protocol) with the shipped weights")
    bench_gamma.add_argument("--quick", action="store_true", help="20 pairs x 8 clones: a few minutes")
    bench_gamma.add_argument("--pairs", type=int, default=100)
    bench_gamma.add_argument("--clones", type=int, default=32)
    bench_gamma.add_argument("--bf16", action="store_true", help="add a row with the prior's networks in bf16")
    bench_gamma.add_argument("--seed", type=int, default=0)
    bench_gamma.add_argument("--precision", default="auto", choices=("auto", "float32", "bfloat16"),
                             help="the prior's networks (auto: bf16 where the CPU has it natively)")
    bench_gamma.add_argument("--output", default=None, help="results file stem under benchmarks/results/ (default gamma_control[_quick])")
    bench_gamma.add_argument("--policies", type=Path, nargs="+", default=None,
                             help="policy .zip files to evaluate instead of the shipped ones (clone rows only, no search rows)")
    bench_gamma.add_argument("--mirror-right-goals", action="store_true",
                             help="bodies whose goal starts on their right live in their mirror image (GammaReach's "
                                  "mirror_right_goals; default output gamma_control_mirror[_quick])")
    bench_gamma.add_argument("--weights-dir", type=Path, default=None,
                             help="a folder with a GAMMA prior and its ppo_gammareach_*.zip policies, used for both "
                                  "(e.g. motion_envs/priors/weights/clean; default: the shipped ones)")  # fmt: skip
    _add_ray_arg(bench_gamma)
    bench_gamma.set_defaults(run=_bench_gamma)
    bench_wandr = bench.add_parser("wandr", help="WANDR goal reaching (the paper's 3,750-rollout grid) with the shipped weights")
    bench_wandr.add_argument("--quick", action="store_true", help="2 start poses x 1 sample (250 rollouts)")
    bench_wandr.add_argument("--seed", type=int, default=0)
    bench_wandr.add_argument("--no-data-fs", action="store_true", help="skip the data's FS row (needs the mocap folder)")
    bench_wandr.add_argument("--no-optimisation", action="store_true", help="skip the latent-optimisation rows (slowest)")
    bench_wandr.add_argument("--no-timing", action="store_true",
                             help="leave out the decode throughput (and throughput.md's section): a busy machine")
    bench_wandr.add_argument("--variants-dir", type=Path, default=Path("runs/wandr_weights"),
                             help="ablation / data-variant weights to add as rows (not shipped)")
    bench_wandr.add_argument("--only", default=None,
                             help="rerun only the grid rows whose label contains this text (e.g. 'PPO') and rewrite them in the existing table")
    _add_ray_arg(bench_wandr)
    bench_wandr.set_defaults(run=_bench_wandr)
    bench_wander = bench.add_parser("wander", help="GAMMA bodies following waypoints: open-ground paths, rooms, a crowd")
    bench_wander.add_argument("--paths", type=int, default=100, help="open-ground waypoint paths")
    bench_wander.add_argument("--rooms", type=int, default=100, help="held-out rooms per layout family (max 100)")
    bench_wander.add_argument("--seed", type=int, default=0)
    bench_wander.add_argument("--quick", action="store_true", help="20 paths x 8 clones, 10 rooms per family, a 10-s crowd")
    bench_wander.add_argument("--policies", type=Path, nargs="+", default=None,
                              help="PPO policies to compare (default: the shipped GammaWander policy, if any, and GammaReach's alpha=1)")
    bench_wander.add_argument("--output", default=None, help="results file stem (default gamma_wander[_quick])")
    bench_wander.set_defaults(run=_bench_wander)
    bench_pace = bench.add_parser("wandr-pace", help="does WANDR's prior keep the intention's pace on its own training windows?")
    bench_pace.add_argument("--weights", type=Path, nargs="+", default=None, help="WANDR priors (default: the shipped one)")
    bench_pace.set_defaults(run=_bench_wandr_pace)
    bench_actions = bench.add_parser("clops-actions", help="how far each CLOPS action carries the body, per prior")
    bench_actions.add_argument("--weights", type=Path, nargs="+", default=None,
                               help="CLOPS priors (default: the shipped one and priors/weights/clean/clops.pt)")
    bench_actions.add_argument("--rooms", type=int, default=8, help="held-out open rooms, one body per room and action")
    bench_actions.set_defaults(run=_bench_clops_actions)
    bench_clops = bench.add_parser("clops", help="CLOPS scene matrix: shipped ClopsNav policies on every family's test seeds")
    bench_clops.add_argument("--episodes", type=int, default=100, help="test seeds per family, one episode each (max 100)")
    bench_clops.add_argument("--families", default=None, help="comma-separated layout families (default: all five)")
    bench_clops.add_argument("--seed", type=int, default=0)
    _add_ray_arg(bench_clops)
    bench_clops.set_defaults(run=_bench_clops)
    video = bench.add_parser("cleanup-video", help="one clip before and after cleanup, side by side (docs/cleanup_<clip>.mp4)")
    video.add_argument("--clip", default="cmu/08_11", help="clip name in the cache (folder/file without suffix)")
    _add_data_args(video, list(SHIPPED_SUBSETS))
    video.set_defaults(run=_bench_cleanup_video)
    turns = bench.add_parser("gamma-turns", help="left and right turns of GAMMA's prior and policy (gamma_turns.md)")
    turns.add_argument("--bodies", type=int, default=1024, help="bodies of the prior's rows (a quarter per policy row)")
    turns.add_argument("--seed", type=int, default=0)
    turns.set_defaults(run=_bench_gamma_turns)
    bench_floor = bench.add_parser("floor", help="feet on the floor in every env, with and without its floor rule (floor.md)")
    bench_floor.add_argument("--steps", type=int, default=2000, help="env steps per row")
    bench_floor.add_argument("--seed", type=int, default=0)
    bench_floor.add_argument("--weights-dir", type=Path, default=None,
                             help="priors to measure (e.g. motion_envs/priors/weights/clean; default: the shipped ones)")
    bench_floor.add_argument("--output", default=None, help="result table name (default floor)")
    bench_floor.set_defaults(run=_bench_floor)
    speed = bench.add_parser("speed", help="GAMMA rollout body-primitives/s by batch, fp32 and bf16 (throughput.md)")
    speed.add_argument("--output", default="throughput", help=THROUGHPUT_OUTPUT_HELP)
    speed.set_defaults(run=_bench_speed)
    bench_rllib = bench.add_parser("rllib", help="PPO steps/s on GammaReach: RLlib env runners vs the SB3 path (rllib.md)")
    bench_rllib.add_argument("--bodies", type=int, default=256, help="bodies per update (default 256)")
    bench_rllib.add_argument("--curve-from", type=Path, default=None,
                             help="instead: write the learning curve of this `train ppo --engine rllib` run folder")
    bench_rllib.set_defaults(run=_bench_rllib)
    bench.add_parser("ray-scaling", help="the full WANDR grid on 1 vs 2 local Ray workers, tables compared (rllib.md)").set_defaults(
        run=_bench_ray_scaling
    )
    bench.add_parser("gpu", help="CUDA: CPU and GPU agree on the same latents; GPU throughput (skips without CUDA)").set_defaults(
        run=_bench_gpu
    )
    render = bench.add_parser("render", help="third-person and egocentric rendering frames/s (benchmarks/results/throughput.md)")
    render.add_argument("--output", default="throughput", help=THROUGHPUT_OUTPUT_HELP)
    render.set_defaults(run=_bench_render)
    realism = bench.add_parser("gamma-realism", help="random-latent GAMMA motion vs the data: contact score, FS")
    _add_data_args(realism, list(SHIPPED_SUBSETS))
    realism.add_argument("--rollouts", type=int, default=10, help="rollouts per shipped start pose")
    realism.add_argument("--weights-dir", type=Path, default=None, help="GAMMA weights to measure (default: the shipped ones)")
    realism.add_argument("--output", default=None, help="result table name (default gamma_realism)")
    realism.add_argument("--primitives", type=int, default=20)
    realism.add_argument("--seed", type=int, default=0)
    realism.set_defaults(run=_bench_gamma_realism)
    feet = bench.add_parser("gamma-feet", help="the GAMMA envs' foot rule on walking bodies: foot skating with and without it")
    feet.add_argument("--bodies", type=int, default=128)
    feet.add_argument("--primitives", type=int, default=30)
    feet.add_argument("--seed", type=int, default=0)
    feet.set_defaults(run=_bench_gamma_feet)

    play = commands.add_parser("play", help="run episodes with a policy or baseline; write a video and a summary")
    play.add_argument("env_id", help="motion_envs/GammaReach-v0, motion_envs/GammaWander-v0, motion_envs/WandrReach-v0 or motion_envs/ClopsNav-v0")
    play.add_argument("--policy", type=Path, default=None, help="a saved policy (.zip: PPOKL, or DQN for ClopsNav)")
    play.add_argument("--baseline", default=None,
                      help="GammaReach: random | greedy-reward | greedy-distance (default random); WandrReach: sampler; ClopsNav: random")
    play.add_argument("--video", type=Path, default=None, help="write an mp4 of every generated frame")
    play.add_argument("--seed", type=int, default=0)
    play.add_argument("--episodes", type=int, default=1)
    play.add_argument("--every", type=int, default=2, help="keep every n-th frame in the video (40 fps / n)")
    play.add_argument("--search", type=int, default=None, metavar="K", help="play a tree search's branch (K kept per level)")
    play.add_argument("--save-rollout", type=Path, default=None, help="write every frame to an .npz for `motion-envs view`")
    play.add_argument("--env-option", action="append", default=[], metavar="KEY=VALUE",
                      help="a gym.make argument of the env, over what the policy was trained for (repeatable)")
    play.set_defaults(run=_play)

    crowd = commands.add_parser("populate", help="fill a room with GAMMA bodies walking between random places")
    crowd.add_argument("--scene", default=None, metavar="FAMILY:SEED", help="a procedural room, e.g. living:1003")
    crowd.add_argument("--scene-file", type=Path, default=None, help="a scene file (any trimesh format) instead")
    crowd.add_argument("--bodies", type=int, default=16)
    crowd.add_argument("--seconds", type=float, default=30.0)
    crowd.add_argument("--seed", type=int, default=0)
    crowd.add_argument("--policy", type=Path, default=None, help="PPO policy proposing latents (default: the shipped GammaWander policy; GammaReach policies work too)")
    crowd.add_argument("--no-search", action="store_true", help="play the policy's latents without tree search")
    crowd.add_argument("--roots", type=int, default=8, help="search: latents tried per body and primitive")
    crowd.add_argument("--horizon", type=int, default=2, help="search: primitives looked ahead")
    crowd.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    crowd.add_argument("--video", type=Path, default=None, help="write an mp4 of the crowd")
    crowd.add_argument("--save-rollout", type=Path, default=None, help="write every frame to an .npz for `motion-envs view`")
    crowd.set_defaults(run=_populate)

    ship = commands.add_parser("ship", help="copy a run's finished weights or policy into the package, with its manifest "
                                            "record and the history of what it replaces")  # fmt: skip
    ship.add_argument("file", type=Path, help="weights or a policy a train command wrote (its run folder's manifest has its record)")
    ship.add_argument("--as", dest="name", default=None, metavar="NAME",
                      help="the shipped file's name (default: the file's own), e.g. ppo_wandrreach_alpha1_default.zip")
    ship.add_argument("--drop-env-option", action="append", default=[], metavar="KEY",
                      help="policies: remove this saved env option (e.g. weights, for a prior shipped as the default) (repeatable)")
    ship.add_argument("--note", default=None, help="a note for the manifest record (what was measured, why it ships)")
    ship.set_defaults(run=_ship)

    view = commands.add_parser("view", help="browser viewer (viser): replay a rollout file or run a policy live")
    view.add_argument("rollout", nargs="?", type=Path, default=None, help="an .npz from `motion-envs play --save-rollout`")
    view.add_argument("--env", default=None,
                      help="run this env live instead: motion_envs/GammaReach-v0, motion_envs/WandrReach-v0 or motion_envs/ClopsNav-v0")
    view.add_argument("--policy", type=Path, default=None, help="live: a saved policy (.zip: PPOKL, or DQN for ClopsNav)")
    view.add_argument("--env-option", action="append", default=[], metavar="KEY=VALUE",
                      help="live: a gym.make argument of the env, over what the policy was trained for (repeatable)")
    view.add_argument("--baseline", default=None, help="live: a baseline name (as `play`)")
    view.add_argument("--seed", type=int, default=0)
    view.add_argument("--scene", default=None, metavar="FAMILY:SEED", help="show a procedural room, e.g. living:3 (default: the rollout's own, if it names one)")
    view.add_argument("--scene-file", type=Path, default=None, help="show a scene file (any trimesh format)")
    view.add_argument("--host", default="127.0.0.1", help="bind address (default 127.0.0.1: this machine only)")
    view.add_argument("--port", type=int, default=8080)
    view.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: until Ctrl-C)")
    view.set_defaults(run=_view)
    return root


def main(argv: list[str] | None = None) -> int:
    """Run a command. An error prints one line naming it (exit 1); `--debug`, anywhere in the line, shows the
    traceback instead."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    args = parser().parse_args([word for word in argv if word != "--debug"])
    keep_freed_memory()  # every command steps or trains batches of the same large tensors (`motion_envs.allocator`)
    try:
        return int(args.run(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as error:  # the one place every command's failure becomes a sentence
        if debug:
            raise
        print(f"motion-envs {args.command}: error: {error} ({type(error).__name__}; --debug shows the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
