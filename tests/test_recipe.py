"""`motion-envs train priors`: the shipped recipe's stages, their commands, skipping finished ones, shipping."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from motion_envs.cli import main
from motion_envs.priors import recipe, training


def test_stages_fill_in_the_weights_they_start_from_and_unknown_ones_fail(tmp_path):
    clops = recipe.stages_named(["clops"])[0]
    argv = recipe.stage_argv(clops, tmp_path, ["--mocap-dir", "m"])
    assert argv[:2] == ["train", "clops"]
    assert argv[argv.index("--prior-init") + 1] == str(tmp_path / "clops_stage2" / "clops.pt")
    assert argv[argv.index("--weights") + 1] == str(tmp_path / "clops" / "clops.pt") and argv[-2:] == ["--mocap-dir", "m"]
    with pytest.raises(ValueError, match="unknown stage.*wandr"):
        recipe.stages_named(["wandr", "nope"])
    assert [s.name for s in recipe.stages_named(None)] == [s.name for s in recipe.RECIPE]


def test_a_stage_needs_the_stages_it_starts_from(tmp_path, capsys):
    assert main(["train", "priors", "--stages", "clops", "--run-dir", str(tmp_path)]) == 1
    assert "starts from clops_stage2" in capsys.readouterr().err


def test_finished_stages_are_skipped_and_shipped_with_their_record(tmp_path, monkeypatch, capsys):
    """A finished stage (its weights in its run folder) is not rerun; --ship copies it and its manifest record.
    The package's weights folder is redirected to a temporary one (shipping must not touch the real one here)."""
    shipped = tmp_path / "weights"
    shipped.mkdir()
    monkeypatch.setattr(training, "WEIGHTS_DIR", shipped)
    stage = recipe.stages_named(["gamma_pose_vae"])[0]
    run = stage.run_dir(tmp_path / "runs")
    run.mkdir(parents=True)
    stage.output(tmp_path / "runs").write_bytes(b"weights")
    (run / "manifest.json").write_text(json.dumps({stage.weights: {"command": "motion-envs train gamma --stage pose-vae"}}))
    assert recipe.train_priors(["gamma_pose_vae"], tmp_path / "runs", ship=True) == 0
    assert "gamma_pose_vae: done" in capsys.readouterr().out
    assert (shipped / stage.weights).read_bytes() == b"weights"
    assert json.loads((shipped / "manifest.json").read_text())[stage.weights]["command"].endswith("pose-vae")


def test_the_clean_priors_load_in_their_envs_and_record_their_data():
    """The retrained priors whose agents are not yet retrained ship beside the defaults (priors/weights/clean/) and
    run where envs are told to load them; each has a manifest record naming its data cache and command. WANDR's and
    GAMMA's clean priors are the defaults now, their records naming the priors they replaced."""
    import gymnasium as gym
    import numpy as np

    import motion_envs  # noqa: F401  (registers the ids)
    from motion_envs.priors.training import CLEAN_WEIGHTS_DIR, WEIGHTS_DIR

    defaults = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    assert "--prior-init" in defaults["wandr.pt"]["command"] and "train wandr" in defaults["wandr.pt"]["replaces"]["command"]
    for name in ("gamma_predictor_1f.pt", "gamma_predictor_2f.pt", "gamma_regressor.pt"):
        assert "uncleaned" in defaults[name]["replaces"]["why"], name
    policy = defaults["ppo_gammareach_alpha1_paper.zip"]  # learnt on the default (clean) GAMMA prior, then fine-tuned
    assert "weights_dir=" not in policy["stages"][0]["command"] and policy["stages"][0]["command"].startswith("motion-envs train ppo")
    assert "--init" in policy["stages"][-1]["command"] and policy["replaces"]["command"] and policy["replaces"]["why"]
    manifest = json.loads((CLEAN_WEIGHTS_DIR / "manifest.json").read_text())
    assert manifest["clops.pt"]["data_hash"].startswith("motion_") and "train" in manifest["clops.pt"]["command"]
    env = gym.make("motion_envs/ClopsNav-v0", weights=str(CLEAN_WEIGHTS_DIR / "clops.pt"))
    env.reset(seed=0)
    env.action_space.seed(0)
    _, reward, *_ = env.step(env.action_space.sample())
    assert np.isfinite(reward)


def test_the_default_wandr_prior_is_the_pace_tuned_one_and_its_policy_was_fine_tuned_on_it(tmp_path, monkeypatch):
    """The shipped WANDR prior is the recipe's last WANDR stage (pace and upright terms) and ships; the stage it
    fine-tunes does not. Its record names the prior it replaced; the PPO policy's record names its fine-tune on
    the shipped prior, its file no longer names a prior (it acts in the default), and played from any directory it
    reaches its goals."""
    from motion_envs.play import play, policy_env_kwargs
    from motion_envs.priors.training import WEIGHTS_DIR

    shipped = [stage for stage in recipe.RECIPE if stage.weights == "wandr.pt" and stage.ships]
    assert [stage.name for stage in shipped] == ["wandr_upright"] and "--pace-weight" in shipped[0].command
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    prior, policy = manifest["wandr.pt"], manifest["ppo_wandrreach_alpha1_default.zip"]
    assert "--pace-weight" in prior["command"] and "--upright-weight" in prior["command"] and prior["data_hash"]
    assert prior["replaces"]["command"] and prior["replaces"]["why"] and prior["note"]
    last_stage = policy["config"]["command"]  # the policy's own run: fine-tuned from a policy, in the prior it ships with
    assert "--init" in last_stage and "--env-option weights=" in last_stage and policy["promoted"]
    file = WEIGHTS_DIR / "ppo_wandrreach_alpha1_default.zip"
    assert "weights" not in policy_env_kwargs("motion_envs/WandrReach-v0", file)[1]
    monkeypatch.chdir(tmp_path)
    summaries = play("motion_envs/WandrReach-v0", file, episodes=4, goal_distance=(1.0, 2.0))
    assert sum(summary["success"] for summary in summaries) >= 3, summaries


def test_the_default_clops_prior_is_the_upright_one_and_its_policies_were_fine_tuned_on_it(tmp_path, monkeypatch):
    """The shipped CLOPS prior is the recipe's `clops_upright` stage (free-running upright, pace and turn terms) keeping
    the shipped action deltas, so that the ClopsNav policies' action indices keep their meaning; each DQN record
    names its fine-tune from the file it replaced (on this prior, or on its predecessor and promoted), its file
    names no prior (it acts in the default one), and played from any directory the goal-memory policy finds the
    goal in held-out rooms."""
    from motion_envs.play import play, policy_env_kwargs
    from motion_envs.priors.training import WEIGHTS_DIR

    shipped = [stage for stage in recipe.RECIPE if stage.weights == "clops.pt" and stage.ships]
    assert [stage.name for stage in shipped] == ["clops_upright"]
    assert shipped[0].command[shipped[0].command.index("--actions-from") + 1] == "shipped"
    manifest = json.loads((WEIGHTS_DIR / "manifest.json").read_text())
    prior = manifest["clops.pt"]
    assert "--upright-weight" in prior["command"] and "--turn-weight" in prior["command"] and "--turn-weight" in shipped[0].command
    assert prior["actions"] and prior["replaces"]["why"] and prior["note"]
    for name in ("dqn_clopsnav_open.zip", "dqn_clopsnav_open_memory.zip", "dqn_clopsnav_open_known_goal.zip",
                 "dqn_clopsnav_mixed.zip"):  # fmt: skip
        command = manifest[name]["config"]["command"]  # fine-tuned on the default prior, or on another and promoted
        assert "--init" in command and ("--env-option weights=" not in command or manifest[name]["promoted"]), name
        assert "weights" not in policy_env_kwargs("motion_envs/ClopsNav-v0", WEIGHTS_DIR / name)[1], name
    monkeypatch.chdir(tmp_path)
    summaries = play("motion_envs/ClopsNav-v0", WEIGHTS_DIR / "dqn_clopsnav_open_memory.zip", episodes=4, split="test")
    assert sum(summary["success"] for summary in summaries) >= 2, summaries
