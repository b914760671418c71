"""Training WANDR's prior (`motion-envs train wandr`).

Reads top to bottom: clips -> windows with hallucinated goals -> statistics
-> epochs of scheduled rollouts -> validation -> weights + manifest.

* Goals (Sec. 3.2, hindsight): a window starting at frame s gets a goal
  frame t_G in the future of its clip; the goal is the right wrist there and
  the goal heading the body's heading there. The release picks t_G among
  frames whose pelvis is ≥ 1.5 m away (REFERENCE_NOTES §2.5) because CIRCLE
  supplies the close reaches; we have no CIRCLE, so with probability
  `far_goal_probability` t_G is drawn that way and otherwise uniformly over
  the next `goal_horizon` frames (reaches in place, short steps).
* Scheduled teacher forcing (Sup. B.2): a batch rolls its windows out for
  `steps` frames, the first from the data, later ones from the model's own
  integrated output (the encoder sees the delta from the predicted pose to
  the next true pose, as the release). `steps` is uniform in 1..k, and k
  grows from 1 to `max_rollout` (10) over the first half of training.
* KL weight: the paper's β = 0.01 gives a posterior the decoder leans on
  (validation KL ~40 nats) and prior samples it has rarely seen: with
  z ~ N(0, I) one decoded frame was worse than repeating the last delta
  (joint error 2.8 cm against 1.5 cm), and sampled bodies bent out of shape
  within 4 s. `late_kl_weight` raises β once the rollouts are long (the
  shipped prior: 0.1 from epoch index 22 of 40; a 5-epoch trial from epoch 18
  kept the mean joint angle at 38-41° for 6 s where β = 0.01 reached 72°).
* Normalisation: z-scores with floors on the standard deviation, 0.05 for
  the condition and 0.01 for the delta. Many 6-D entries barely move in the
  data (std ~1e-3); with a tiny floor a 1 cm / 0.5° slip of the model's own
  rollout became a 10σ input and sampled motion fell apart within 4 s
  (pelvis height 5-95% after 8 s: −0.1 to 0.85 m with feet kept on the floor).
* Loss (Sec. 3.4): per frame, reconstruction MSE of the normalised delta
  (translation, orientation and pose averaged separately, then summed, as
  the release) + joint MSE in cm through our FK; plus β·KL with free bits
  (0.05 per dimension) and β ramped 0 → 1e-2 as the release's 2^(t/T) − 1.
* Pace (ours, off by default: `pace_weight`): every loss above sees the
  posterior's z, while samplers and policies draw z ~ N(0, I), and with it
  the prior walked at half the data's pace on its own training windows
  (`bench wandr-pace`). The pace term rolls a few windows per batch out for
  `pace_frames` frames with z ~ N(0, I) and pulls the pelvis's ground
  distance to the data's pelvis at the goal frame towards the data's own
  distance at the same frame: it asks for the data's progress, not its path
  (`free_run_terms`, which also holds `upright_weight`'s term: the head's
  height above the feet against the data's, and `turn_weight`'s: the
  pelvis's heading gap to the goal frame's against the data's, the pace of
  turning, which the pelvis distance hardly sees).
  Measured (shipped prior fine-tuned 4 epochs with the `wandr` stage's
  settings, lr 1e-4, 90-frame pace rollouts; `bench wandr-pace`): weight
  0.01 / 0.03 leave 0.44 / 0.37 m to go after 6 s (shipped 0.80, the data
  0.34; validation pace gap 87 -> 47 / 38 cm), but a 15-s sampled walk
  sinks more (`bench floor`'s head over the 15th second 1.42 -> 1.40 /
  1.24 m, lowest head 0.98 -> 0.47 / 0.18 m): the faster gait folds some
  bodies. With the upright term as well (pace 0.03, upright 0.3): 0.43 m
  left after 6 s and the 15-s walk's head at 1.45 m (lowest 1.23 m): the
  recipe's `wandr_paced` stage. Rerun on the data with the Daz files' pelvis
  tilt turned back (cleanup step 3): 0.31 m left after 6 s (the data 0.30),
  head over the 15th second 1.44 m (lowest 1.18 m); fine-tuned again with the
  upright term at 1.0 (`wandr_upright`, the shipped prior): 0.33 m, head
  1.48 m (lowest 1.26 m); with upright 0.3 and the turn term at 0.1 instead,
  1.40 m (lowest 0.14 m).
* Reach (ours, off by default: `reach_weight`, `end_goal_probability`): the
  8-s protocol's sampled bodies arrive on time but their wrist ends 0.2-0.3 m
  off at the deadline. The reach term pulls the free run's wrist-to-goal
  distance towards the data's at the same frame; with a share of free runs
  whose goal is due at their last frame (the protocol's case) the data's
  wrist arrives there. With 90-frame free runs it lifts the 8-s sampler
  (8% -> 18-25% on 500 rollouts) but lowers the 15-s walk's head by 2-13 cm;
  with 150-frame ones (R = 1, P = 0.5) 28% with the head kept (1.48 m); not
  in the shipped prior yet (figures: `benchmarks/wandr_grid.py`'s module doc).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from motion_envs.body import BodyModel, joint_index
from motion_envs.body.rotations import rotation_matrix
from motion_envs.data.dataset import MotionDataset
from motion_envs.data.motion import BodyMotion
from motion_envs.priors.training import WEIGHTS_DIR, TrainRun, fit, load_shipped, minibatches, seed_everything, ship
from motion_envs.priors.clops import yaw_change
from motion_envs.priors.wandr import WandrConfig, WandrPrior
from motion_envs.body.markers import sole_vertex_ids
from motion_envs.data.paths import SHIPPED_SUBSETS
from motion_envs.priors.wandr_features import (
    FPS, INTENTIONS, PELVIS, RIGHT_WRIST, WandrState, condition, integrate, intention, make_state, pose_delta,
)  # fmt: skip

WANDR_KIND = "wandr"
HEAD = joint_index("head")
FOOT_JOINTS = [joint_index(name) for name in ("left_ankle", "right_ankle", "left_foot", "right_foot")]
FAR_GOAL_DISTANCE = 1.5
FREE_RUN_TERMS = ("pace", "upright", "turn", "reach")
"""`free_run_terms`' gaps; each has a `<name>_weight` in `WandrTrainConfig`."""


@dataclass
class WandrTrainConfig(TrainRun):
    """Settings of one WANDR training run (paper: 900 epochs, batch 512, lr 1e-4 → 1e-5)."""

    model: WandrConfig = field(default_factory=WandrConfig)
    epochs: int = 40
    batch_size: int = 256
    learning_rate: float = 3e-4
    final_learning_rate: float = 3e-5
    max_rollout: int = 10
    goal_horizon: int = 8 * FPS
    far_goal_probability: float = 0.5
    condition_std_floor: float = 0.05
    delta_std_floor: float = 0.01
    kl_weight: float = 1e-2
    kl_warmup_steps: int = 2000
    late_kl_weight: float | None = None
    """β from `kl_raise_epoch` on (None: `kl_weight` throughout). See the module doc."""
    kl_raise_epoch: int = 0
    free_bits: float = 0.05
    window_stride: int = 1
    contact_weight: float = 1.0
    """Weight of `contact_slide` (cm², like the joint term) in the loss; 0 turns the contact loss off."""
    pace_weight: float = 0.0
    """Weight of `free_run_terms`' pace (cm², like the joint term; 0: off). See the module doc."""
    upright_weight: float = 0.0
    """Weight of `free_run_terms`' upright gap (cm²; 0: off)."""
    turn_weight: float = 0.0
    """Weight of `free_run_terms`' turn gap (centiradians², like the cm² terms; 0: off)."""
    reach_weight: float = 0.0
    """Weight of `free_run_terms`' reach gap (cm²; 0: off): the right wrist's distance to its goal against the data's."""
    end_goal_probability: float = 0.0
    """Share of free runs whose goal is due at the run's last frame (the paper's protocol: every goal due when the
    episode ends); the others' goals are at least `pace_frames` ahead. See the module doc."""
    pace_frames: int = 90
    """Frames of each free-running rollout (its windows have a goal at least this far ahead)."""
    pace_windows: int = 64
    """Windows per batch rolled out for `free_run_terms`."""
    init: Path | None = None
    """Prior weights of the same network to start from (None: from scratch)."""
    run_dir: Path = Path("runs/wandr")

    def __post_init__(self) -> None:
        if min(self.free_run_weights.values()) < 0 or self.pace_frames < 1 or self.pace_windows < 1:
            raise ValueError(f"pace_weight, upright_weight, turn_weight and reach_weight must be ≥ 0 and pace_frames, "
                             f"pace_windows ≥ 1, got {self.free_run_weights}, {self.pace_frames}, {self.pace_windows}")  # fmt: skip
        if not 0.0 <= self.end_goal_probability <= 1.0:
            raise ValueError(f"end_goal_probability must be in [0, 1], got {self.end_goal_probability}")

    @property
    def free_run_weights(self) -> dict[str, float]:
        """{term: weight} of every `FREE_RUN_TERMS` gap in the loss."""
        return {name: getattr(self, f"{name}_weight") for name in FREE_RUN_TERMS}

    @property
    def free_running(self) -> bool:
        """Whether batches roll windows out with z ~ N(0, I) (`free_run_terms`)."""
        return max(self.free_run_weights.values()) > 0

    def rollout_limit(self, epoch: int) -> int:
        """k of the schedule: 1 at the start, `max_rollout` from half-way on."""
        ramp = max(1, self.epochs // 2)
        return max(1, min(self.max_rollout, round(self.max_rollout * epoch / ramp)))

    def kl_beta(self, step: int, epoch: int) -> float:
        if self.late_kl_weight is not None and epoch >= self.kl_raise_epoch:
            return self.late_kl_weight
        if step >= self.kl_warmup_steps:
            return self.kl_weight
        return self.kl_weight * (2 ** (step / self.kl_warmup_steps) - 1)


@dataclass(frozen=True)
class WandrClips:
    """Clips of one split, frames concatenated.

    transl: (F, 3). orient: (F, 3, 3). pose: (F, 21, 3, 3). joints: (F, 22, 3).
    clip_end: (F,) one past the last frame of each frame's clip. contacts: (F, 4) bool sole contacts
    (`SOLE_POINTS` order; all False for uncleaned data).
    """

    transl: torch.Tensor
    orient: torch.Tensor
    pose: torch.Tensor
    joints: torch.Tensor
    clip_end: torch.Tensor
    contacts: torch.Tensor

    @classmethod
    def from_motions(cls, clips: list[BodyMotion], body: BodyModel) -> WandrClips:
        if not clips:
            raise ValueError("no clips to train on")
        if {c.fps for c in clips} != {FPS}:
            raise ValueError(f"WANDR trains on {FPS} fps motion, got {sorted({c.fps for c in clips})} fps")
        transl, orient, pose = (torch.as_tensor(np.concatenate([getattr(c, name) for c in clips]), dtype=torch.float32)
                                for name in ("transl", "global_orient", "body_pose"))  # fmt: skip
        with torch.no_grad():
            joints = body(transl, orient, pose).joints
        lengths = torch.tensor([c.num_frames for c in clips])
        clip_end = torch.repeat_interleave(torch.cumsum(lengths, 0), lengths)
        contacts = torch.as_tensor(np.concatenate([c.info.get("contacts", np.zeros((c.num_frames, 4), bool)) for c in clips]))
        return cls(transl, rotation_matrix(orient), rotation_matrix(pose), joints, clip_end, contacts)

    @classmethod
    def from_dataset(cls, dataset: MotionDataset, split: str, body: BodyModel, mirrored: bool = False) -> WandrClips:
        return cls.from_motions(dataset.clips(split, mirrored=mirrored), body)

    def window_starts(self, steps: int, stride: int = 1) -> torch.Tensor:
        """(W,) frames s with a previous frame in their clip and `steps` frames after them."""
        frames = torch.arange(1, len(self.transl), stride)
        has_previous = self.clip_end[frames - 1] == self.clip_end[frames]
        return frames[has_previous & (frames + steps < self.clip_end[frames])]

    def state(self, frames: torch.Tensor) -> WandrState:
        """The data's state at `frames` (B,): its pose and the delta into it."""
        before = frames - 1
        delta = pose_delta(self.transl[before], self.orient[before], self.pose[before],
                           self.transl[frames], self.orient[frames], self.pose[frames])  # fmt: skip
        return WandrState(self.transl[frames], self.orient[frames], self.pose[frames], delta, self.joints[frames], self.pose[frames])

    def sample_goal_frames(self, starts: torch.Tensor, steps: int, horizon: int, far_probability: float,
                           generator: torch.Generator | None = None) -> torch.Tensor:  # fmt: skip
        """(B,) goal frames t_G in [s + steps, s + horizon] inside each window's clip (see the module doc)."""
        offsets = torch.arange(steps, horizon + 1)
        candidates = starts[:, None] + offsets  # (B, H)
        inside = candidates < self.clip_end[starts][:, None]
        candidates = torch.where(inside, candidates, starts[:, None] + steps)
        travel = (self.joints[candidates, PELVIS, :2] - self.joints[starts, PELVIS, :2][:, None]).norm(dim=-1)
        far = inside & (travel >= FAR_GOAL_DISTANCE)
        want_far = (torch.rand(len(starts), generator=generator) < far_probability)[:, None] & far.any(1, keepdim=True)
        allowed = torch.where(want_far, far, inside)
        weights = torch.rand(allowed.shape, generator=generator) * allowed  # argmax of random weights: uniform
        return candidates.gather(1, weights.argmax(1, keepdim=True)).squeeze(1)


def goal_heading(orient: torch.Tensor) -> torch.Tensor:
    """(B, 2) ground forward of pelvis rotations (B, 3, 3)."""
    return orient[:, :2, 1]


class HindsightTargets(Protocol):
    """What a delta prior is conditioned on, hallucinated from the data's own future (WANDR's wrist goals,
    CLOPS's head targets): goal frames for windows, and the 9 condition features towards them."""

    def goal_frames(self, starts: torch.Tensor, steps: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """(B,) goal frames for windows starting at `starts` (B,) that roll out `steps` frames."""
        ...

    def features(self, state: WandrState, frames: torch.Tensor, goal_frames: torch.Tensor) -> torch.Tensor:
        """(B, 9) features of bodies `state` (now at data frames `frames`, (B,)) towards their goal frames (B,)."""
        ...

    def free_run_goal_frames(self, starts: torch.Tensor, step: int, frames: int, goal_frames: torch.Tensor) -> torch.Tensor:
        """(B,) the goal frames a `frames`-frame free run (`free_run_terms`) from `starts` heads for at its `step`
        (0-based), given `goal_frames(starts, frames)`, as the envs hand out goals."""
        ...


@dataclass(frozen=True)
class WristGoals:
    """WANDR's targets: the right wrist at t_G and the heading there (see the module doc)."""

    clips: WandrClips
    config: WandrTrainConfig

    def goal_frames(self, starts: torch.Tensor, steps: int, generator: torch.Generator | None = None) -> torch.Tensor:
        return self.clips.sample_goal_frames(starts, steps, self.config.goal_horizon, self.config.far_goal_probability,
                                             generator)  # fmt: skip

    def features(self, state: WandrState, frames: torch.Tensor, goal_frames: torch.Tensor) -> torch.Tensor:
        goal = self.clips.joints[goal_frames, RIGHT_WRIST]
        return intention(state.joints, state.orient, goal, goal_frames - frames, goal_heading(self.clips.orient[goal_frames]),
                         self.config.model.intentions)  # fmt: skip

    def free_run_goal_frames(self, starts: torch.Tensor, step: int, frames: int, goal_frames: torch.Tensor) -> torch.Tensor:
        return goal_frames  # one goal for the whole run, as WandrReach's episodes


def rollout_terms(model: WandrPrior, clips: WandrClips, targets: HindsightTargets, starts: torch.Tensor,
                  goal_frames: torch.Tensor, steps: int, body: BodyModel, free_bits: float,
                  sample: bool = True) -> dict[str, torch.Tensor]:  # fmt: skip
    """Mean per-frame losses of rolling windows out for `steps` frames (the first from the data).

    Returns recon, joints (cm²), kl (with free bits), contact (cm², see `contact_slide`) and joint_error_cm
    (steps,) per frame (no grad).
    """
    state = clips.state(starts)
    soles = sole_vertex_ids()
    previous_soles = body.skin(body.from_matrices(state.transl, state.orient, state.pose), soles)
    totals = {"recon": 0.0, "joints": 0.0, "kl": 0.0, "contact": 0.0}
    errors = []
    for step in range(steps):
        cond = model.normalise_condition(condition(state, targets.features(state, starts + step, goal_frames)))
        nxt = starts + step + 1
        target = pose_delta(state.transl, state.orient, state.pose, clips.transl[nxt], clips.orient[nxt], clips.pose[nxt])
        target = model.normalise_delta(target)
        mean, log_variance = model.encode(cond, target)
        z = mean + torch.randn_like(mean) * torch.exp(0.5 * log_variance) if sample else mean
        predicted = model.decode(z, cond)
        squared = (predicted - target) ** 2
        totals["recon"] = totals["recon"] + squared[:, :3].mean() + squared[:, 3:9].mean() + squared[:, 9:].mean()
        prior_mean, prior_log_variance = model.prior(cond)  # KL(q(z | c, d) ‖ p(z | c)), p = N(0, I) for WANDR
        kl_per_dim = 0.5 * (((mean - prior_mean) ** 2 + log_variance.exp()) / prior_log_variance.exp() - 1
                            - log_variance + prior_log_variance).mean(0)  # fmt: skip
        totals["kl"] = totals["kl"] + kl_per_dim.clamp_min(free_bits).sum()
        delta = model.denormalise_delta(predicted)
        state, posed = make_state(body, *integrate(state.transl, state.orient, state.pose, delta), delta)
        now_soles = body.skin(posed, soles)
        totals["contact"] = totals["contact"] + contact_slide(previous_soles, now_soles, clips.contacts[nxt - 1] & clips.contacts[nxt])
        previous_soles = now_soles
        offset = (state.joints - clips.joints[nxt]) * 100.0
        totals["joints"] = totals["joints"] + (offset**2).mean()
        errors.append(offset.detach().norm(dim=-1).mean())
    terms = {name: value / steps for name, value in totals.items()}
    terms["joint_error_cm"] = torch.stack(errors)
    return terms


def free_run_terms(model: WandrPrior, clips: WandrClips, targets: HindsightTargets, starts: torch.Tensor, frames: int,
                   body: BodyModel, generator: torch.Generator | None = None,
                   end_goal_probability: float = 0.0) -> dict[str, torch.Tensor]:  # fmt: skip
    """Mean squared gaps (cm²) to the data over a rollout of `frames` frames with z ~ N(0, I) from the data at
    `starts` (B,), towards the goal frames `targets.free_run_goal_frames` hands out (WANDR: one at least `frames`
    ahead, or with `end_goal_probability` the run's last frame; CLOPS: the next action's end; see the module doc):

    * pace: how far the pelvis is from its goal (on the ground, to the data's pelvis at the goal frame) against how
      far the data's is at the same frame;
    * upright: the head's height above the lowest ankle or foot joint against the data's at the same frame.
    * turn: how far the pelvis's heading is from the goal frame's (ground yaw, centiradians) against how far the
      data's is at the same frame: the pace term's progress for turning, which moves the pelvis little.
    * reach: how far the right wrist is from the goal frame's (3-D) against how far the data's is at the same
      frame: where the goal is due at the run's end, the data's wrist arrives there, and so must the prior's.

    The gradient reaches each frame's delta only (the state it starts from is detached): back-propagated through
    the whole rollout, the pace term blew the fine-tune up within two epochs (training loss 16 -> 1,125,
    reconstruction 1.4 -> 744, at weights 0.003 and 0.01)."""
    run_goal_frames = targets.goal_frames(starts, frames, generator)
    if end_goal_probability > 0:  # no draw otherwise: runs without end goals keep their random stream
        at_end = torch.rand(len(starts), generator=generator) < end_goal_probability
        run_goal_frames = torch.where(at_end, starts + frames, run_goal_frames)
    state = clips.state(starts)
    totals = dict.fromkeys(FREE_RUN_TERMS, 0.0)
    for step in range(frames):
        goal_frames = targets.free_run_goal_frames(starts, step, frames, run_goal_frames)
        goal_joints, goal_orient = clips.joints[goal_frames], clips.orient[goal_frames]
        goal = goal_joints[:, PELVIS, :2]
        cond = model.normalise_condition(condition(state, targets.features(state, starts + step, goal_frames)))
        noise = torch.randn(len(starts), model.config.latent, generator=generator)
        delta = model.denormalise_delta(model.generate(noise, cond))
        state, _ = make_state(body, *integrate(state.transl, state.orient, state.pose, delta), delta)
        data = clips.joints[starts + step + 1]
        left = (state.joints[:, PELVIS, :2] - goal).norm(dim=-1)
        totals["pace"] = totals["pace"] + ((left - (data[:, PELVIS, :2] - goal).norm(dim=-1)) * 100.0).pow(2).mean()
        gap = head_height(state.joints) - head_height(data)
        totals["upright"] = totals["upright"] + (gap * 100.0).pow(2).mean()
        turn_left = yaw_change(state.orient, goal_orient).abs()
        data_turn_left = yaw_change(clips.orient[starts + step + 1], goal_orient).abs()
        totals["turn"] = totals["turn"] + ((turn_left - data_turn_left) * 100.0).pow(2).mean()
        wrist_goal = goal_joints[:, RIGHT_WRIST]
        reach_left = (state.joints[:, RIGHT_WRIST] - wrist_goal).norm(dim=-1)
        totals["reach"] = totals["reach"] + ((reach_left - (data[:, RIGHT_WRIST] - wrist_goal).norm(dim=-1)) * 100.0).pow(2).mean()
        state = WandrState(*(value.detach() for value in state))
    return {name: total / frames for name, total in totals.items()}


def head_height(joints: torch.Tensor) -> torch.Tensor:
    """(B,) the head's height above the lowest ankle or foot joint of bodies' joints (B, 22, 3)."""
    return joints[:, HEAD, 2] - joints[:, FOOT_JOINTS, 2].amin(dim=-1)


def contact_slide(before: torch.Tensor, after: torch.Tensor, contacts: torch.Tensor) -> torch.Tensor:
    """Mean squared horizontal step (cm²) of the sole points (B, 4, 3) from one frame to the next where the
    data holds them in contact at both (B, 4) (0 where none is): cleaned data holds them still there, so this
    pulls a generated stance foot to rest (the contact loss of issue "Clean motion")."""
    step = ((after[..., :2] - before[..., :2]) * 100.0).pow(2).sum(-1)
    return (step * contacts).sum() / contacts.sum().clamp_min(1)


@torch.no_grad()
def fit_statistics(model: WandrPrior, clips: WandrClips, targets: HindsightTargets, config: WandrTrainConfig,
                   max_samples: int = 50_000) -> None:  # fmt: skip
    """z-score statistics of the teacher-forced conditions and deltas of (up to `max_samples`) training windows."""
    starts = clips.window_starts(1)
    starts = starts[torch.randperm(len(starts))[:max_samples]]
    state = clips.state(starts)
    features = targets.features(state, starts, targets.goal_frames(starts, 1))
    nxt = starts + 1
    deltas = pose_delta(state.transl, state.orient, state.pose, clips.transl[nxt], clips.orient[nxt], clips.pose[nxt])
    model.set_statistics(condition(state, features), deltas, config.condition_std_floor, config.delta_std_floor)


@torch.no_grad()
def validate(model: WandrPrior, clips: WandrClips, targets: HindsightTargets, config: WandrTrainConfig, body: BodyModel,
             max_windows: int = 1024) -> dict[str, float | list[float]]:  # fmt: skip
    """Posterior-mean reconstruction of validation windows: one teacher-forced frame and a `max_rollout` rollout;
    and the root mean `free_run_terms` of z ~ N(0, I) rollouts (cm)."""
    model.eval()
    generator = torch.Generator().manual_seed(0)
    figures: dict[str, float | list[float]] = {}
    for steps in (1, config.max_rollout):
        starts = clips.window_starts(steps)
        starts = starts[torch.linspace(0, len(starts) - 1, min(max_windows, len(starts))).long()]
        goal_frames = targets.goal_frames(starts, steps, generator)
        terms = rollout_terms(model, clips, targets, starts, goal_frames, steps, body, config.free_bits, sample=False)
        if steps == 1:
            figures |= {"validation_recon": round(float(terms["recon"]), 5), "validation_kl": round(float(terms["kl"]), 4),
                        "validation_joint_error_cm_1_frame": round(float(terms["joint_error_cm"][0]), 3)}  # fmt: skip
        else:
            figures["validation_joint_error_cm_rollout"] = [round(float(e), 2) for e in terms["joint_error_cm"]]
    starts = clips.window_starts(config.pace_frames)
    if len(starts):
        starts = starts[torch.linspace(0, len(starts) - 1, min(max_windows // 4, len(starts))).long()]
        for name, value in free_run_terms(model, clips, targets, starts, config.pace_frames, body, generator).items():
            unit = "crad" if name == "turn" else "cm"  # the turn gap is an angle (centiradians)
            figures[f"validation_{name}_gap_{unit}_{config.pace_frames}_frames"] = round(float(value.sqrt()), 2)
        at_end = free_run_terms(model, clips, targets, starts, config.pace_frames, body, generator, end_goal_probability=1.0)
        figures[f"validation_reach_gap_cm_goal_due_at_frame_{config.pace_frames}"] = round(float(at_end["reach"].sqrt()), 2)
    model.train()
    return figures


def default_weights(config: WandrConfig, subsets: tuple[str, ...] = SHIPPED_SUBSETS) -> str:
    """The weights' file name: wandr.pt for the full model on CMU; ablations and data variants get suffixes."""
    suffix = "" if tuple(config.intentions) == INTENTIONS else "_" + "_".join(config.intentions)
    data = "" if tuple(subsets) in ((), SHIPPED_SUBSETS) else "_" + "_".join(subsets)
    return f"wandr{suffix}{data}.pt"


def train_wandr(config: WandrTrainConfig, train: WandrClips, validation: WandrClips) -> dict:
    """Train (or resume) WANDR's prior; returns the manifest entry it writes."""
    seed_everything(config.seed)
    model = WandrPrior(config.model)
    if config.init is not None:
        missing, unexpected = model.load_state_dict(load_wandr(config.init).state_dict(), strict=False)
        if unexpected or any(not name.startswith("prior_network.") for name in missing):  # only a new prior network may be missing
            raise ValueError(f"{config.init} is not the same network as {config.model}: missing {missing}, unexpected {unexpected}")
    return train_delta_prior(model, WANDR_KIND, config, train, validation, lambda clips: WristGoals(clips, config),
                             config.output(default_weights(config.model)))  # fmt: skip


def train_delta_prior(model: WandrPrior, kind: str, config: WandrTrainConfig, train: WandrClips, validation: WandrClips,
                      targets_of: Callable[[WandrClips], HindsightTargets], weights: Path) -> dict:  # fmt: skip
    """The training loop shared by the per-frame delta priors (WANDR, CLOPS): statistics, scheduled rollouts,
    linear lr decay, validation, ship to `weights`; returns the manifest entry."""
    body = BodyModel()
    train_targets = targets_of(train)
    fit_statistics(model, train, train_targets, config)
    optimiser = torch.optim.Adam(model.parameters(), lr=config.learning_rate)
    batches_per_epoch = len(minibatches(train.window_starts(config.max_rollout, config.window_stride), config.batch_size,
                                        torch.Generator()))  # fmt: skip
    total_steps = batches_per_epoch * config.epochs
    decay = config.final_learning_rate / config.learning_rate

    pace_starts = train.window_starts(config.pace_frames, config.window_stride)
    if config.free_running and len(pace_starts) == 0:
        raise ValueError(f"no training window has {config.pace_frames} frames for the free-running terms (pace_frames)")

    def epoch_batches(epoch: int, generator: torch.Generator) -> list[tuple[torch.Tensor, int, int, torch.Tensor]]:
        starts = train.window_starts(config.max_rollout, config.window_stride)
        limit = config.rollout_limit(epoch)
        steps = torch.randint(1, limit + 1, (batches_per_epoch,), generator=generator).tolist()
        batches = minibatches(starts, config.batch_size, generator)
        paced = [pace_starts[torch.randint(len(pace_starts), (min(config.pace_windows, len(pace_starts)),), generator=generator)]
                 if config.free_running else pace_starts[:0] for _ in batches]  # fmt: skip
        return [(b, epoch * batches_per_epoch + i, s, p) for i, (b, s, p) in enumerate(zip(batches, steps, paced))]

    def loss_terms(epoch: int, batch: tuple[torch.Tensor, int, int, torch.Tensor]) -> dict[str, torch.Tensor]:
        starts, step_number, steps, paced = batch
        for group in optimiser.param_groups:  # linear decay, as the paper's 1e-4 -> 1e-5
            group["lr"] = config.learning_rate * (1 + (decay - 1) * step_number / total_steps)
        goal_frames = train_targets.goal_frames(starts, steps)
        terms = rollout_terms(model, train, train_targets, starts, goal_frames, steps, body, config.free_bits)
        beta = config.kl_beta(step_number, epoch)
        terms |= (free_run_terms(model, train, train_targets, paced, config.pace_frames, body,
                                 end_goal_probability=config.end_goal_probability) if len(paced)
                  else {name: torch.zeros(()) for name in FREE_RUN_TERMS})  # fmt: skip
        total = terms["recon"] + terms["joints"] + beta * terms["kl"] + config.contact_weight * terms["contact"]
        for name, weight in config.free_run_weights.items():  # one by one, in FREE_RUN_TERMS order
            total = total + weight * terms[name]
        return {"total": total} | {name: terms[name] for name in ("recon", "joints", "kl", "contact", *FREE_RUN_TERMS)}

    history = fit(model, optimiser, config.fit_settings(kind), epoch_batches, loss_terms,
                  lambda epoch: f"rollout ≤ {config.rollout_limit(epoch)}")  # fmt: skip
    entry = config.entry(kind, model.config, history, **validate(model, validation, targets_of(validation), config, body))
    return ship(model, weights, entry)


def load_wandr(path: str | Path | None = None) -> WandrPrior:
    """A trained prior from shipped weights (default: the full model, priors/weights/wandr.pt)."""
    path = WEIGHTS_DIR / "wandr.pt" if path is None else path

    def build(stored: dict) -> WandrPrior:
        return WandrPrior(WandrConfig(**{**stored, "intentions": tuple(stored["intentions"])}))

    return load_shipped(path, WANDR_KIND, build)
