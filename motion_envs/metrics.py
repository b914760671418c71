"""Motion metrics shared by benchmarks and environments (batched torch)."""

from __future__ import annotations

import torch

WANDR_SKATING_THRESHOLD = 2.0 / 3.0 * 0.01
"""WANDR's FS threshold: 0.66 cm between consecutive frames at 30 fps (0.2 m/s)."""


def lowest_foot(feet: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The lowest of each body's foot vertices (N, V, 3): its index (N,) and ground position (N, 2)."""
    index = feet[..., 2].contiguous().argmin(dim=-1)  # contiguous: `loaded_slide`'s note
    return index, feet[torch.arange(len(feet), device=feet.device), index, :2]


def track_skating(feet: torch.Tensor, lowest_id: torch.Tensor, lowest_xy: torch.Tensor,
                  active: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:  # fmt: skip
    """One frame of WANDR's FS, streamed: did the vertex that was lowest (`lowest_id` (N,), at `lowest_xy` (N, 2))
    slide more than the threshold to this frame's feet (N, V, 3)? Returns skated (N,) bool (False where not
    `active`) and the new lowest vertex and position (kept where not `active`)."""
    rows = torch.arange(len(feet), device=feet.device)
    slide = (feet[rows, lowest_id, :2] - lowest_xy).norm(dim=-1)
    index, xy = lowest_foot(feet)
    keep = active[:, None]
    return (slide > WANDR_SKATING_THRESHOLD) & active, torch.where(active, index, lowest_id), torch.where(keep, xy, lowest_xy)


def skating_threshold(fps: float) -> float:
    """WANDR's FS threshold at another frame rate: the same 0.2 m/s, in metres per frame."""
    return WANDR_SKATING_THRESHOLD * 30.0 / fps


def foot_skating(feet: torch.Tensor, threshold: float = WANDR_SKATING_THRESHOLD) -> torch.Tensor:
    """WANDR's foot skating per frame transition.

    The lowest foot vertex of frame t skates if that same vertex moves more
    than `threshold` metres horizontally by frame t + 1 (no height gating, as
    in the WANDR release).

    Args:
        feet: (..., T, V, 3) foot vertex positions (see `body.markers.foot_vertex_ids`).

    Returns:
        (..., T - 1) bool, True where the frame skates. FS is its mean.
    """
    lowest = feet[..., :-1, :, 2].contiguous().argmin(dim=-1, keepdim=True)  # (..., T-1, 1); `loaded_slide`'s note
    index = lowest[..., None].expand(*lowest.shape, 2)
    now = torch.gather(feet[..., :-1, :, :2], -2, index)
    then = torch.gather(feet[..., 1:, :, :2], -2, index)
    return (then - now).norm(dim=-1).squeeze(-1) > threshold


CONTACT_HEIGHT = 0.05
CONTACT_SPEED = 0.075
"""GAMMA Eq. 11 thresholds: 5 cm above the ground, 7.5 cm/s."""


def contact_score(markers: torch.Tensor, fps: float, slowest: torch.Tensor | None = None) -> torch.Tensor:
    """GAMMA's contact score (Eq. 11) of each primitive.

    s = exp(-(min |Y_z| - 0.05)+) · exp(-(min |Y_vel| - 0.075)+), minima over
    the primitive's frames and markers; speeds by forward difference.

    Args:
        markers: (N, T, M, 3) markers of N primitives, ground at z = 0.
        fps: frame rate of the markers.
        slowest: (N,) `slowest_marker_speed(markers, fps)` where the caller has it already.

    Returns:
        (N,) scores in (0, 1], higher is better.
    """
    lowest = markers[..., 2].abs().amin(dim=(1, 2))
    slowest = slowest_marker_speed(markers, fps) if slowest is None else slowest
    return torch.exp(-(lowest - CONTACT_HEIGHT).clamp_min(0.0)) * torch.exp(-(slowest - CONTACT_SPEED).clamp_min(0.0))


def slowest_marker_speed(markers: torch.Tensor, fps: float, central: bool = False) -> torch.Tensor:
    """(N, T, M, 3) -> (N,) the slowest marker speed (m/s) of each primitive, over its frames and markers, by
    forward or central differences (the square root taken of the minimum only)."""
    step = markers[:, 2:] - markers[:, :-2] if central else markers[:, 1:] - markers[:, :-1]
    return step.square_().sum(-1).amin(dim=(1, 2)).sqrt() * (fps / 2.0 if central else fps)  # in place: step is new


LOADED_HEIGHT = 0.025
"""A sole point within this height (m) of the local floor can bear weight (`loaded_foot_skating`)."""
LOADED_SPEED = 0.2
"""Horizontal speed (m/s) above which a loaded sole point skates: WANDR's 0.66 cm per frame at 30 fps."""


def local_floor(heights: torch.Tensor, fps: float, seconds: float = 1.0) -> torch.Tensor:
    """(..., T) the lowest of `heights` (..., T) within +-seconds/2 of each frame: the floor the feet stand on,
    wherever a clip's or a prior's ground drifts (and on steps)."""
    window = max(1, int(round(seconds * fps))) | 1
    flat = heights.reshape(-1, 1, heights.shape[-1])
    lowest = -torch.nn.functional.max_pool1d(-flat, window, stride=1, padding=window // 2)
    return lowest.reshape(heights.shape)


def loaded_foot_skating(soles: torch.Tensor, fps: float, height: float = LOADED_HEIGHT,
                        speed: float = LOADED_SPEED) -> torch.Tensor:  # fmt: skip
    """Contact-aware foot skating per frame transition: the loaded foot slides.

    WANDR's FS counts every frame whose lowest foot vertex moves, so a heel landing or a foot rolling from heel
    to toe (the lowest vertex travels along the sole) counts as skating, and clean capture scores 46%. Here
    fixed sole points count, and only the one bearing the weight: at frame t the loaded point is the lowest of
    the four (the heel or the toe of the loaded foot); a transition skates when that same point is within
    `height` of the local floor (`local_floor` of the lowest sole point) at t and t + 1 and moves horizontally
    faster than `speed`. A point pivoting about itself does not move, so heel strikes, roll-offs and turns on
    the spot do not count.

    Args:
        soles: (..., T, 4, 3) sole points in `body.markers.SOLE_POINTS` order (left heel, left toe, right heel,
            right toe), or any two points per foot in that layout (the raw sources: ankle and toe joints).
        fps: their frame rate.

    Returns:
        (..., T - 1) bool, True where the loaded foot skates. Its mean is the contact-aware FS.
    """
    return loaded_slide(soles, fps, height, speed) > 0


def loaded_slide(soles: torch.Tensor, fps: float, height: float = LOADED_HEIGHT, speed: float = LOADED_SPEED) -> torch.Tensor:
    """(..., T - 1) m/s by which the loaded sole point slides faster than `speed` (0 where it does not skate):
    `loaded_foot_skating`'s measure, graded. soles: (..., T, 4, 3) as there."""
    z = soles[..., 2].contiguous()  # argmin over a strided last axis takes a slow path (1.7 ms against 0.09 ms at
    # 1,024 x 9 x 4, 2 cores, torch 2.13)
    floor = local_floor(z.amin(-1), fps)
    lowest = z[..., :-1, :].argmin(-1, keepdim=True)  # (..., T-1, 1): the loaded foot's lower point
    now = soles[..., :-1, :, :].gather(-2, lowest[..., None].expand(*lowest.shape, 3)).squeeze(-2)
    then = soles[..., 1:, :, :].gather(-2, lowest[..., None].expand(*lowest.shape, 3)).squeeze(-2)
    near = (now[..., 2] - floor[..., :-1] < height) & (then[..., 2] - floor[..., 1:] < height)
    excess = (then[..., :2] - now[..., :2]).norm(dim=-1) * fps - speed
    return torch.where(near, excess.clamp_min(0.0), torch.zeros_like(excess))


def stance_ankle_speed(ankles: torch.Tensor, fps: float) -> torch.Tensor:
    """Median horizontal speed (m/s) of the stance ankle over (T, 2, 3) ankle positions (left, right): per
    frame the lower ankle stands, over the transitions where it stays the same one (the measure of
    `shared/mocap/README.md`). Clean walking capture: 0.15 m/s; NaN for fewer than two frames."""
    lower = ankles[..., 2].argmin(-1)  # (T,)
    same = lower[:-1] == lower[1:]
    step = (ankles[1:, :, :2] - ankles[:-1, :, :2]).norm(dim=-1) * fps  # (T-1, 2)
    stance = step.gather(-1, lower[:-1, None]).squeeze(-1)[same]
    return stance.median() if len(stance) else torch.tensor(float("nan"))


def window_speeds(track: torch.Tensor, frames: torch.Tensor, fps: float, seconds: float = 0.5) -> tuple[torch.Tensor, torch.Tensor]:
    """Ground speeds (m/s) over every span of `seconds` of pelvis tracks, and which spans lie within each track.

    track: (N, T + 1, 2) pelvis ground positions, frame 0 to T (a body that ended early keeps its last one);
    frames: (N,) frames each body moved (its spans end at or before it).
    Returns speeds (N, S) with S = T + 1 − round(seconds · fps) (S ≥ 0) and a bool mask (N, S), True for spans
    inside the body's frames.
    """
    window = round(seconds * fps)
    if track.shape[1] <= window:
        empty = track.new_zeros(len(track), 0)
        return empty, empty.bool()
    speeds = (track[:, window:] - track[:, :-window]).norm(dim=-1) / (window / fps)
    ends = torch.arange(window, track.shape[1], device=track.device)
    return speeds, ends[None] <= frames[:, None].to(track.device)
