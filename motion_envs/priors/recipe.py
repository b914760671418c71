"""`motion-envs train priors`: rebuild every shipped prior from a mocap folder with its shipped recipe.

Each stage is one `motion-envs train ...` command (run as a child process, so
its manifest records that command) writing into `runs/priors/<stage>/`. A stage
whose weights are already there is skipped and an interrupted one resumes from
its checkpoint (every train command does), so rerunning `train priors` after a
kill continues where it stopped. With `--ship` each finished stage's weights and
manifest record are copied into `motion_envs/priors/weights/` (`ship_trained`,
naming what they replace); intermediate stages (each prior's all but its last) are not shipped.

`minutes` is the wall time measured for the stage on 2 cores (one thread each,
two stages at a time) on the shipped data (CMU + ACCAD, 147 clips); a larger
mocap folder scales it roughly with its number of frames. The GAMMA predictors'
stages are the run measured best on the cleaned data (8 single-primitive epochs,
no rollout fine-tuning, no contact loss: random-latent FS 0.214 against the
previous recipe's 25 + 3 epochs with the contact loss, 0.60); the previous
recipe's 25 + 3 epochs without the contact loss was not tried on the cleaned data. `gamma_heading` measures the
predictors' heading calibration with the regressor (`motion_envs.priors.gamma_heading`) on the same data.
WANDR's prior is trained with rollouts of at most 10 frames (`wandr_short`), then fine-tuned with rollouts of up
to 60 (`wandr_60`) and 120 frames (`wandr`): trained on 0.33 s of its own output only, it folded over within 15 s
of sampled walking (trunk tilt 36° and growing, head 0.53 m over the 15th second of a walk towards a goal 20 m
ahead; after the 60-frame fine-tune ~20° and 1.13 m; a goal 15 m ahead, the issue's protocol: 1.22 m after the
60-frame fine-tune, 1.42 m after the 120-frame one). It still walked at half the data's pace (0.80 m left after
6 s, the data 0.34): `wandr_paced` fine-tunes it with the free-running pace and upright terms
(`train_wandr.free_run_terms`; 0.43 m, head 1.45 m over a 15-s walk's last second), and `wandr_upright` again with
the upright term at 1.0 (head 1.48 m, lowest 1.26, where `wandr_paced` gave 1.44 and 1.18 on the tilt-fixed data;
same pace). `wandr_60`'s 10 minutes are estimated from its last epochs alone (1.3 s a batch; the measured run
shared the cores with a data build: 34 minutes); `wandr`'s 24 were measured beside another training on the other
core, as were `wandr_paced`'s 23 and `wandr_upright`'s 16. CLOPS starts from `wandr_short`, as its shipped prior
did, and gets the same fine-tune (`clops`: rollouts of up to 60 frames, 8 minutes measured alone), then its own
free-running terms (`clops_upright`: upright 1.0, pace 0.1 and turn 0.1 over 150-frame free runs of 1-s actions,
`train_clops`; 23 minutes beside another training): on the tilt-fixed data `clops` alone let ClopsNav's 15-s
forward walk sink (head over the last second 1.12 m, bodies falling); after `clops_upright` 1.48 m (lowest 1.09;
without the turn term 1.41 m, and its small turning actions were slow: module doc of `train_clops`).
`clops_upright` keeps the shipped prior's action deltas (`--actions-from shipped`): ClopsNav's policies act by
action index, and the shipped ones were fine-tuned with them (`motion-envs train dqn --init`). It is the shipped
CLOPS prior.

The shipped WANDR prior is these five stages on the data after cleanup turned back the Daz files' pelvis tilt
(`motion_envs.data.cleanup`, step 3; the first four rerun as `runs/priors_tilt`, `wandr_upright` fine-tuned from
its `wandr_paced`): pace 0.33 m left after 6 s (`bench wandr-pace`; `wandr_paced` 0.31, the data 0.30); the 8-s
sampler (3,750 rollouts) SR 8.6% / FS 17.3% (`wandr_paced` 10.2% / 16.0%, the prior before the tilt fix 6.2% /
21.3%), the paced sampler 62.0% (68.3%, 84.5%); head over the last second of a 15-s walk 1.48 m (1.44). CLOPS's
shipped prior is `clops_upright` on the same data; GAMMA's were trained on the data before that step (each
manifest's `data_hash` names its cache).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from motion_envs.priors.training import ship_trained

RUNS = Path("runs/priors")


@dataclass(frozen=True)
class Stage:
    """name: also its run folder. command: the train arguments (without --run-dir/--weights/--ship/data
    options; "{stage}" stands for that stage's weights). weights: the file it writes. needs: stages whose
    weights it starts from. ships: whether `--ship` ships it (not an intermediate stage's)."""

    name: str
    command: tuple[str, ...]
    weights: str
    minutes: float | None
    needs: tuple[str, ...] = ()
    ships: bool = True

    def arguments(self, root: Path) -> list[str]:
        """`command` with the "{stage}" placeholders filled in."""
        outputs = {other.name: str(other.output(root)) for other in RECIPE}
        return [word.format(**outputs) for word in self.command]

    def run_dir(self, root: Path) -> Path:
        return root / self.name

    def output(self, root: Path) -> Path:
        return self.run_dir(root) / self.weights


WANDR_FREE_RUN_FINE_TUNE = ("--epochs", "4", "--max-rollout", "120", "--window-stride", "2", "--late-kl-weight", "0.1",
                            "--kl-raise-epoch", "0", "--pace-weight", "0.03", "--learning-rate", "1e-4")
"""The WANDR stages after `wandr` (free-running pace term, 120-frame rollouts); each adds its upright weight."""


RECIPE: tuple[Stage, ...] = (
    Stage("wandr_short", ("wandr", "--epochs", "40", "--window-stride", "2", "--late-kl-weight", "0.1", "--kl-raise-epoch", "22"),
          "wandr.pt", 20, ships=False),
    Stage("wandr_60", ("wandr", "--prior-init", "{wandr_short}", "--epochs", "6", "--max-rollout", "60", "--window-stride", "2",
                       "--late-kl-weight", "0.1", "--kl-raise-epoch", "0"), "wandr.pt", 10, needs=("wandr_short",), ships=False),
    Stage("wandr", ("wandr", "--prior-init", "{wandr_60}", "--epochs", "6", "--max-rollout", "120", "--window-stride", "2",
                    "--late-kl-weight", "0.1", "--kl-raise-epoch", "0"), "wandr.pt", 24, needs=("wandr_60",), ships=False),
    Stage("wandr_paced", ("wandr", "--prior-init", "{wandr}", *WANDR_FREE_RUN_FINE_TUNE, "--upright-weight", "0.3"), "wandr.pt",
          23, needs=("wandr",), ships=False),
    Stage("wandr_upright", ("wandr", "--prior-init", "{wandr_paced}", *WANDR_FREE_RUN_FINE_TUNE, "--upright-weight", "1.0"),
          "wandr.pt", 16, needs=("wandr_paced",)),
    Stage("clops_stage1", ("clops", "--prior-init", "{wandr_short}"), "clops.pt", 6, needs=("wandr_short",), ships=False),
    Stage("clops_stage2", ("clops", "--prior-init", "{clops_stage1}", "--max-rollout", "30", "--epochs", "6"), "clops.pt", 7,
          needs=("clops_stage1",), ships=False),
    Stage("clops", ("clops", "--prior-init", "{clops_stage2}", "--max-rollout", "60", "--epochs", "6", "--window-stride", "2"),
          "clops.pt", 8, needs=("clops_stage2",), ships=False),
    Stage("clops_upright", ("clops", "--prior-init", "{clops}", "--max-rollout", "60", "--epochs", "4", "--window-stride", "2",
                            "--learning-rate", "1e-4", "--upright-weight", "1.0", "--pace-weight", "0.1", "--turn-weight", "0.1",
                            "--pace-frames", "150", "--actions-from", "shipped"), "clops.pt", 23, needs=("clops",)),
    Stage("gamma_predictor_1f", ("gamma", "--stage", "predictor", "--seed-frames", "1", "--epochs", "8", "--rollout-epochs", "0"),
          "gamma_predictor_1f.pt", 5),
    Stage("gamma_predictor_2f", ("gamma", "--stage", "predictor", "--seed-frames", "2", "--epochs", "8", "--rollout-epochs", "0"),
          "gamma_predictor_2f.pt", 5),
    Stage("gamma_regressor", ("gamma", "--stage", "regressor", "--epochs", "46", "--batch-size", "16", "--window-stride", "4"),
          "gamma_regressor.pt", 20),
    Stage("gamma_heading", ("gamma", "--stage", "heading", "--predictor-1f", "{gamma_predictor_1f}", "--predictor-2f",
                            "{gamma_predictor_2f}", "--regressor", "{gamma_regressor}"), "gamma_heading_calibration.pt", 2,
          needs=("gamma_predictor_1f", "gamma_predictor_2f", "gamma_regressor")),
    Stage("gamma_pose_vae", ("gamma", "--stage", "pose-vae", "--epochs", "20"), "gamma_pose_vae.pt", 1),
    Stage("gamma_g_cvae_2f", ("gamma", "--stage", "g-cvae", "--epochs", "12"), "gamma_g_cvae_2f.pt", None),
)  # fmt: skip
"""The shipped priors' recipe, in an order that respects `needs`."""


def stages_named(names: list[str] | None) -> list[Stage]:
    """The recipe's stages with these names (all when None), in recipe order; an unknown name is an error."""
    known = {stage.name: stage for stage in RECIPE}
    unknown = sorted(set(names or ()) - set(known))
    if unknown:
        raise ValueError(f"unknown stage(s) {', '.join(unknown)}; the stages are {', '.join(known)}")
    return [stage for stage in RECIPE if names is None or stage.name in names]


def stage_argv(stage: Stage, root: Path, passed_args: list[str]) -> list[str]:
    """The `motion-envs` argument list of one stage, ending in `passed_args` (data folder, subsets, threads)."""
    return ["train", *stage.arguments(root), "--run-dir", str(stage.run_dir(root)), "--weights",
            str(stage.output(root)), *passed_args]  # fmt: skip


def plan(stages: list[Stage], root: Path) -> list[str]:
    """One line per stage: done or to run, with its expected wall time."""
    lines = []
    for stage in stages:
        state = "done" if stage.output(root).exists() else "to run"
        expected = f"~{stage.minutes:.0f} min" if stage.minutes is not None else "time not measured yet"
        lines.append(f"  {stage.name:20s} {state:7s} {expected:24s} motion-envs train {' '.join(stage.arguments(root))}")
    return lines


def train_priors(names: list[str] | None = None, root: Path = RUNS, ship: bool = False,
                 passed_args: list[str] | None = None) -> int:  # fmt: skip
    """Run the stages in order (skipping finished ones); returns the first failing stage's exit code, or 0."""
    stages = stages_named(names)
    print("stages (expected wall time on 2 cores):", *plan(stages, root), sep="\n")
    for stage in stages:
        missing = [need for need in stage.needs if not next(s for s in RECIPE if s.name == need).output(root).exists()]
        if missing:
            raise RuntimeError(f"stage {stage.name} starts from {', '.join(missing)}, which has not been trained in {root}")
        if stage.output(root).exists():
            print(f"{stage.name}: done ({stage.output(root)})")
        else:
            argv = stage_argv(stage, root, passed_args or [])
            print(f"{stage.name}: motion-envs {' '.join(argv)}", flush=True)
            code = subprocess.call([sys.executable, "-m", "motion_envs.cli", *argv])
            if code != 0:
                print(f"{stage.name} failed (exit {code}); rerun the same command to resume it", file=sys.stderr)
                return code
        if ship and stage.ships:
            ship_trained(stage.output(root))
    return 0
