"""Where the motion-capture folder and the data cache live."""

from __future__ import annotations

import os
from pathlib import Path

MOCAP_ENV_VAR = "MOTION_ENVS_DATA"
CACHE_ENV_VAR = "MOTION_ENVS_CACHE"


def default_mocap_dir() -> Path | None:
    """`$MOTION_ENVS_DATA`, else `shared/mocap` beside the checkout (or beside the working
    directory), else None."""
    if os.environ.get(MOCAP_ENV_VAR):
        return Path(os.environ[MOCAP_ENV_VAR]).expanduser()
    for root in (Path(__file__).resolve().parents[2], Path.cwd()):
        beside = root.parent / "shared" / "mocap"
        if beside.is_dir():
            return beside
    return None


def default_cache_dir() -> Path:
    """`$MOTION_ENVS_CACHE`, else `~/.cache/motion_envs`."""
    return Path(os.environ.get(CACHE_ENV_VAR, Path.home() / ".cache" / "motion_envs")).expanduser()


SHIPPED_SUBSETS: tuple[str, ...] = ("cmu", "cmu_extra", "accad")
"""The mocap subfolders the shipped weights train on (CMU in both formats and ACCAD, whose licences allow
shipping weights; HDM05 is share-alike and stays for ablations), where the mocap folder has them."""

