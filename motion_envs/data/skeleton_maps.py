"""Declarative joint maps from known mocap skeletons to the body's 22 joints.

A map is picked by the skeleton's joint names: every source joint it names
must exist. Each body joint maps to one source joint (at the start of its
bone; BVH end sites are joints named `<parent>_end`) or to None when the
source has no counterpart (the body keeps that joint's local rotation at
rest and its children absorb the difference).
"""

from __future__ import annotations

from dataclasses import dataclass

from motion_envs.body.skeleton import JOINT_NAMES


@dataclass(frozen=True)
class SkeletonMap:
    """How one source skeleton drives the body.

    name: shown in reports. joints: body joint name -> source joint name or None.
    leading_frames_to_skip: frames the converter prepended (e.g. a T-pose).
    subject_skeleton: whether each file's skeleton is its subject's own; False for a converter that puts every
    subject on one figure (cleanup then corrects the pelvis tilt, `motion_envs.data.cleanup.untilt_pelvis`).
    Sources are Y up (retargeting lifts them with `Y_UP_TO_Z_UP`); their rest
    pose and facing may differ from the body's.
    """

    name: str
    joints: dict[str, str | None]
    leading_frames_to_skip: int = 0
    subject_skeleton: bool = True

    def __post_init__(self) -> None:
        if tuple(self.joints) != JOINT_NAMES:
            raise ValueError(f"map {self.name!r} must list the body joints in order: {JOINT_NAMES}")
        if self.joints["pelvis"] is None:
            raise ValueError(f"map {self.name!r} must map the pelvis")

    def source_names(self) -> set[str]:
        return {name for name in self.joints.values() if name is not None}


CMU_DAZ_BVH = SkeletonMap(
    name="CMU cgspeed Daz-friendly BVH",
    joints={
        "pelvis": "hip", "left_hip": "lThigh", "right_hip": "rThigh", "spine1": "abdomen",
        "left_knee": "lShin", "right_knee": "rShin", "spine2": "chest", "left_ankle": "lFoot",
        "right_ankle": "rFoot", "spine3": None, "left_foot": "lFoot_end", "right_foot": "rFoot_end",
        "neck": "neck", "left_collar": "lCollar", "right_collar": "rCollar", "head": "head",
        "left_shoulder": "lShldr", "right_shoulder": "rShldr", "left_elbow": "lForeArm",
        "right_elbow": "rForeArm", "left_wrist": "lHand", "right_wrist": "rHand",
    },  # fmt: skip
    leading_frames_to_skip=1,  # the converter's added T-pose
    subject_skeleton=False,  # every subject on Daz's Aiko3 figure, hip rotations from the pre-retargeting files
)

CMU_ACCLAIM = SkeletonMap(
    name="CMU-style Acclaim ASF/AMC",
    joints={
        "pelvis": "root", "left_hip": "lfemur", "right_hip": "rfemur", "spine1": "upperback",
        "left_knee": "ltibia", "right_knee": "rtibia", "spine2": "thorax", "left_ankle": "lfoot",
        "right_ankle": "rfoot", "spine3": None, "left_foot": "ltoes", "right_foot": "rtoes",
        "neck": "upperneck", "left_collar": "lclavicle", "right_collar": "rclavicle", "head": "head",
        "left_shoulder": "lhumerus", "right_shoulder": "rhumerus", "left_elbow": "lradius",
        "right_elbow": "rradius", "left_wrist": "lwrist", "right_wrist": "rwrist",
    },  # fmt: skip
)

CMU_MAX_BVH = SkeletonMap(
    name="CMU cgspeed 3dsMax-friendly BVH",
    joints={
        "pelvis": "Hips", "left_hip": "LeftHip", "right_hip": "RightHip", "spine1": "Chest",
        "left_knee": "LeftKnee", "right_knee": "RightKnee", "spine2": "Chest2", "left_ankle": "LeftAnkle",
        "right_ankle": "RightAnkle", "spine3": None, "left_foot": "LeftToe", "right_foot": "RightToe",
        "neck": "Neck", "left_collar": "LeftCollar", "right_collar": "RightCollar", "head": "Head",
        "left_shoulder": "LeftShoulder", "right_shoulder": "RightShoulder", "left_elbow": "LeftElbow",
        "right_elbow": "RightElbow", "left_wrist": "LeftWrist", "right_wrist": "RightWrist",
    },  # fmt: skip
)
"""The Acclaim layout under other names (lowerback/upperback/thorax = lowerback/Chest/Chest2); no added T-pose."""

ACCAD_BVH = SkeletonMap(
    name="ACCAD MoCap Lab BVH",
    joints={
        "pelvis": "Hips", "left_hip": "LeftUpLeg", "right_hip": "RightUpLeg", "spine1": "ToSpine",
        "left_knee": "LeftLeg", "right_knee": "RightLeg", "spine2": "Spine", "left_ankle": "LeftFoot",
        "right_ankle": "RightFoot", "spine3": "Spine1", "left_foot": "LeftToeBase", "right_foot": "RightToeBase",
        "neck": "Neck", "left_collar": "LeftShoulder", "right_collar": "RightShoulder", "head": "Head",
        "left_shoulder": "LeftArm", "right_shoulder": "RightArm", "left_elbow": "LeftForeArm",
        "right_elbow": "RightForeArm", "left_wrist": "LeftHand", "right_wrist": "RightHand",
    },  # fmt: skip
)
"""22 joints; its rest pose bends the trunk 90° forward and faces +X (retargeting's rest alignment absorbs it)."""

KNOWN_MAPS: tuple[SkeletonMap, ...] = (CMU_DAZ_BVH, CMU_ACCLAIM, CMU_MAX_BVH, ACCAD_BVH)

class UnknownSkeletonError(ValueError):
    """No known map fits a skeleton; the message lists its joints."""

def match_skeleton(joint_names: tuple[str, ...] | list[str], source: str = "") -> SkeletonMap:
    """The first known map whose source joints all exist in `joint_names`."""
    present = set(joint_names)
    for candidate in KNOWN_MAPS:
        if candidate.source_names() <= present:
            return candidate
    known = ", ".join(m.name for m in KNOWN_MAPS)
    raise UnknownSkeletonError(
        f"{source or 'skeleton'}: no joint map fits its joints ({', '.join(joint_names)}); "
        f"known skeletons: {known}. Add a SkeletonMap to motion_envs/data/skeleton_maps.py."
    )
