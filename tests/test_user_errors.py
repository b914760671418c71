"""What a new user or a hostile tester hits first: policies for the wrong env, commands that fail, bad files.

Each test names the defect it guards against (issue "What a user hits first")."""

from __future__ import annotations

import subprocess
import sys
import zipfile

import pytest

from agents.policy_files import PolicyFileError, expect_policy, read_policy_file
from motion_envs.play import CLOPS_ID, GAMMA_ID, WANDR_ID, LiveEpisodes, play
from motion_envs.priors.training import WEIGHTS_DIR

MEMORY_POLICY = WEIGHTS_DIR / "dqn_clopsnav_open_memory.zip"
KNOWN_GOAL_POLICY = WEIGHTS_DIR / "dqn_clopsnav_open_known_goal.zip"
GAMMA_POLICY = WEIGHTS_DIR / "ppo_gammareach_alpha1_paper.zip"
WANDR_POLICY = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"


def _cli(*words: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "motion_envs.cli", *words], capture_output=True, text=True, timeout=timeout)


def test_play_builds_the_env_each_clops_policy_was_trained_for():
    """`play ClopsNav-v0 --policy <memory or known-goal policy>` crashed inside SB3: the env lacked the options."""
    assert read_policy_file(MEMORY_POLICY).trained_for.env_kwargs["goal_memory"] is True
    assert read_policy_file(KNOWN_GOAL_POLICY).trained_for.env_kwargs["known_goal"] is True
    for policy in (MEMORY_POLICY, KNOWN_GOAL_POLICY):
        (summary,) = play(CLOPS_ID, policy, seed=0, max_seconds=3.0)  # an env option on top of the policy's own
        assert summary["frames"] <= 90 and isinstance(summary["success"], bool)
    live = LiveEpisodes(CLOPS_ID, MEMORY_POLICY)
    assert live.env.config.goal_memory and live.more().frames >= 30


def test_a_policy_for_another_env_or_of_another_kind_fails_before_the_first_step(tmp_path):
    """Wrong policies failed deep inside SB3 or torch, some only after the episode had started."""
    with pytest.raises(PolicyFileError, match="trained for motion_envs/WandrReach-v0.*not motion_envs/GammaReach-v0"):
        play(GAMMA_ID, WANDR_POLICY)
    with pytest.raises(PolicyFileError, match="holds a PPO latent policy.*needs a ClopsNav DQN policy"):
        play(CLOPS_ID, GAMMA_POLICY)
    with pytest.raises(PolicyFileError, match="holds a ClopsNav DQN policy"):
        play(WANDR_ID, MEMORY_POLICY)
    with pytest.raises(PolicyFileError, match="expects the observation space Dict"):
        play(CLOPS_ID, MEMORY_POLICY, goal_memory=False)  # overriding what it was trained for
    with pytest.raises(FileNotFoundError, match=r"nope\.zip$"):  # SB3 alone looks for nope.zip.zip
        expect_policy(tmp_path / "nope.zip", GAMMA_ID, "ppo_policy")
    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(b"not a zip at all")
    with pytest.raises(PolicyFileError, match="garbage.zip is not a saved Stable-Baselines3 policy"):
        read_policy_file(garbage)
    empty = tmp_path / "empty.zip"
    with zipfile.ZipFile(empty, "w") as archive:
        archive.writestr("data", "{}")
    with pytest.raises(PolicyFileError, match="empty.zip"):
        read_policy_file(empty)


def test_cli_errors_are_one_line_with_a_nonzero_exit_and_debug_shows_the_traceback():
    """Every CLI error was a raw traceback."""
    failed = _cli("play", CLOPS_ID, "--policy", str(GAMMA_POLICY))
    assert failed.returncode == 1 and "Traceback" not in failed.stderr
    (line,) = failed.stderr.strip().splitlines()
    assert line.startswith("motion-envs play: error:") and "needs a ClopsNav DQN policy" in line
    debug = _cli("play", CLOPS_ID, "--policy", str(GAMMA_POLICY), "--debug")
    assert debug.returncode == 1 and "Traceback" in debug.stderr and "PolicyFileError" in debug.stderr


def test_a_write_killed_midway_leaves_a_temporary_file_that_the_next_write_removes(tmp_path):
    """A SIGKILL during a checkpoint save left an orphan `.checkpoint.pt.*.tmp` that nothing ever cleaned."""
    target = tmp_path / "checkpoint.pt"
    killed = subprocess.run([sys.executable, "-c", (
        "import os, signal, sys\nfrom motion_envs.atomic import atomic_write\n"
        "def write(file):\n    file.write(b'half')\n    file.flush()\n    os.kill(os.getpid(), signal.SIGKILL)\n"
        f"atomic_write({str(target)!r}, write)\n")], timeout=60)  # fmt: skip
    assert killed.returncode == -9
    orphans = list(tmp_path.glob(".checkpoint.pt.*.tmp*"))
    assert len(orphans) == 1 and not target.exists()
    from motion_envs.atomic import atomic_write

    atomic_write(target, lambda file: file.write(b"whole"))
    assert target.read_bytes() == b"whole" and list(tmp_path.glob(".checkpoint.pt.*")) == []


def test_a_failed_video_leaves_no_file_behind(tmp_path, monkeypatch):
    """`play --video` wrote the mp4 in place: a failed run left a truncated video. The failure is injected after a
    real episode has written its frames (the one stand-in here: checked inputs leave no public way to make an
    episode fail midway)."""
    import motion_envs.play as playing

    real_episode = playing._episode

    def episode_then_failure(*args, **kwargs):
        real_episode(*args, **kwargs)
        raise RuntimeError("stopped after the first episode")

    monkeypatch.setattr(playing, "_episode", episode_then_failure)
    video = tmp_path / "out.mp4"
    with pytest.raises(RuntimeError, match="stopped"):
        play(GAMMA_ID, video=video, max_primitives=1, every=4)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(playing, "_episode", real_episode)
    play(GAMMA_ID, video=video, max_primitives=1, every=4)
    assert video.stat().st_size > 1000 and [path.name for path in tmp_path.iterdir()] == ["out.mp4"]
