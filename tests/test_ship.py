"""`motion-envs ship`: a run's weights or policy into the package, with the history of what it replaces.

The package's weights folder is redirected to a temporary one in every test (shipping must not touch the real one)."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import pytest

from agents.policy_files import read_policy_file
from motion_envs.cli import main
from motion_envs.priors import training

POLICY = "ppo_wandrreach_alpha1_default.zip"
"""The smallest shipped policy (2 MB): a real SB3 file whose saved env options the tests edit."""


@pytest.fixture
def package(tmp_path, monkeypatch) -> Path:
    """A temporary stand-in for priors/weights/ holding one shipped policy with a two-stage history."""
    folder = tmp_path / "weights"
    folder.mkdir()
    monkeypatch.setattr(training, "WEIGHTS_DIR", folder)
    shutil.copy(_real(POLICY), folder)
    first = {"command": "train A", "timesteps": 10, "shipped": "last", "curve": [{"timesteps": 10, "success_rate": 0.5}]}
    shipped = {"config": {"command": "train B", "init": str(folder / POLICY)}, "timesteps": 20, "shipped": "last",
               "curve": [{"timesteps": 20, "success_rate": 0.7}], "machine": "m", "stages": [first], "repeat": "train A && train B"}  # fmt: skip
    (folder / "manifest.json").write_text(json.dumps({POLICY: shipped}))
    return folder


def _real(name: str) -> Path:
    return Path(training.__file__).parent / "weights" / name


def _run(folder: Path, name: str, record: dict, env_options: dict | None = None, copy_of: str = POLICY) -> Path:
    """A run folder holding `name` (a copy of the shipped policy `copy_of`, its saved env options replaced when
    given) and its manifest record."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    with zipfile.ZipFile(_real(copy_of)) as source, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            contents = source.read(item.filename)
            if item.filename == "data" and env_options is not None:
                data = json.loads(contents)
                data["trained_for"]["env_kwargs"] = env_options
                contents = json.dumps(data).encode()
            target.writestr(item, contents)
    (folder / "manifest.json").write_text(json.dumps({name: record}))
    return path


def test_a_fine_tune_of_the_shipped_policy_keeps_its_history(package, tmp_path, capsys):
    record = {"config": {"command": "train C", "init": str(package / POLICY)}, "timesteps": 30, "curve": []}
    run = _run(tmp_path / "runs", "ppo_finetuned.zip", record)
    assert main(["ship", str(run), "--as", POLICY, "--note", "measured"]) == 0
    assert f"replacing the shipped {package / POLICY}" in capsys.readouterr().err
    shipped = json.loads((package / "manifest.json").read_text())[POLICY]
    assert [stage["command"] for stage in shipped["stages"]] == ["train A", "train B"]
    assert shipped["stages"][1]["last_window"] == {"timesteps": 20, "success_rate": 0.7}
    assert shipped["repeat"] == "train A && train B && train C" and shipped["note"] == "measured"
    assert (package / POLICY).read_bytes() == run.read_bytes()


def test_a_fresh_run_names_what_it_replaces(package, tmp_path):
    run = _run(tmp_path / "runs", POLICY, {"config": {"command": "train D", "init": None}, "timesteps": 5, "curve": []})
    assert main(["ship", str(run)]) == 0
    shipped = json.loads((package / "manifest.json").read_text())[POLICY]
    assert shipped["replaces"]["command"] == "train B" and shipped["replaces"]["last_window"]["success_rate"] == 0.7
    assert "stages" not in shipped


def test_a_policy_trained_on_a_run_folder_prior_ships_only_without_that_option(package, tmp_path, capsys):
    options = {"reward": "default", "weights": "runs/prior/wandr.pt"}
    record = {"config": {"command": "train E", "init": str(package / POLICY), "env_kwargs": {"weights": "runs/prior/wandr.pt"}}}
    run = _run(tmp_path / "runs", "ppo_on_new_prior.zip", record, options)
    before = (package / POLICY).read_bytes()
    assert main(["ship", str(run), "--as", POLICY]) == 1
    assert "--drop-env-option weights" in capsys.readouterr().err and (package / POLICY).read_bytes() == before
    assert main(["ship", str(run), "--as", POLICY, "--drop-env-option", "weights"]) == 0
    assert read_policy_file(package / POLICY).trained_for.env_kwargs == {"reward": "default"}
    assert "weights" in json.loads((package / "manifest.json").read_text())[POLICY]["promoted"]
    assert main(["ship", str(run), "--as", POLICY, "--drop-env-option", "scene"]) == 1
    assert "not trained with the env option(s) ['scene']" in capsys.readouterr().err
    both = _run(tmp_path / "runs", "ppo_on_two.zip", record, {**options, "weights_dir": "runs/prior"})
    assert main(["ship", str(both), "--as", POLICY, "--drop-env-option", "weights"]) == 1  # weights_dir still named
    assert "--drop-env-option weights_dir" in capsys.readouterr().err
    assert read_policy_file(package / POLICY).trained_for.env_kwargs == {"reward": "default"}  # the one shipped above


def test_a_file_without_a_record_is_refused(package, tmp_path, capsys):
    stray = tmp_path / "stray.pt"
    stray.write_bytes(b"weights")
    assert main(["ship", str(stray)]) == 1
    assert "has no record" in capsys.readouterr().err and not (package / "stray.pt").exists()


def test_train_ship_into_the_package_names_what_it_replaces(package):
    """`train ... --ship` writes through `training.ship` (priors) and `ship_policy` (policies) straight into the
    package: the record there keeps the history of the one it replaces, as `motion-envs ship` does."""
    from torch import nn

    weights = package / "tiny.pt"
    training.ship(nn.Linear(2, 2), weights, {"kind": "tiny", "command": "train one"})
    assert "replaces" not in json.loads((package / "manifest.json").read_text())["tiny.pt"]
    training.ship(nn.Linear(2, 2), weights, {"kind": "tiny", "command": "train two"})
    record = json.loads((package / "manifest.json").read_text())["tiny.pt"]
    assert record["command"] == "train two" and record["replaces"]["command"] == "train one"


def test_bench_gamma_runs_a_policy_trained_with_mirrored_goals_mirrored(tmp_path):
    """A policy trained with `--env-option mirror_right_goals=true` knows only goals on its left: `bench gamma`
    must run it so (as a heading-calibrated one on the calibrated prior) and say so in its label."""
    from benchmarks.gamma_control import MIRRORED_RIGHT_GOALS, policy_label, trained_with

    shipped = "ppo_gammareach_alpha1_paper.zip"
    mirrored = _run(tmp_path, "mirrored.zip", {}, {"reward": "paper", "mirror_right_goals": True}, copy_of=shipped)
    assert trained_with(mirrored, "mirror_right_goals") and not trained_with(_real(shipped), "mirror_right_goals")
    assert policy_label(mirrored) == "policy(1)" + MIRRORED_RIGHT_GOALS
