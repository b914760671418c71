"""The fixed train/validation/test split, by subject.

Known CMU subjects are assigned by hand so that every split holds walking
(validation: 07 walk + 11 soccer; test: 08 walk + 12 walk). Any other subject
(a user's own folder) goes to a split chosen by a stable hash of its name,
80 / 10 / 10.
"""

from __future__ import annotations

import hashlib

SPLITS = ("train", "validation", "test")

CMU_SUBJECT_SPLIT: dict[str, str] = {
    "02": "train", "03": "train", "05": "train", "06": "train", "09": "train", "10": "train",
    "13": "train", "14": "train", "07": "validation", "11": "validation", "08": "test", "12": "test",
}  # fmt: skip


def split_of(subject: str) -> str:
    """The split a subject's clips belong to."""
    if subject in CMU_SUBJECT_SPLIT:
        return CMU_SUBJECT_SPLIT[subject]
    bucket = int(hashlib.sha256(subject.encode()).hexdigest(), 16) % 10
    return "train" if bucket < 8 else ("validation" if bucket == 8 else "test")
