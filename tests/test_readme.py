"""Every Python snippet of README.md runs verbatim in a fresh interpreter from a folder outside the repository.

The one change: training lengths are shrunk (`shrink_training`, the switch README.md names): the number given to
`.learn(...)` becomes `SHORT_TRAINING` steps, and an SB3 `PPO(...)` collects `SHORT_TRAINING` steps per rollout
(its default 2,048 would outlast the shrunk `.learn`: 58 s of single-body GammaReach steps on 2 cores), so the
snippets that train a policy run in seconds, not hours."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
SHORT_TRAINING = 64


def python_snippets() -> list[tuple[int, str]]:
    """(line, code) of every ```python block in README.md."""
    snippets, lines = [], README.read_text().splitlines()
    start = None
    for number, line in enumerate(lines, start=1):
        if line.strip() == "```python":
            start = number
        elif line.strip() == "```" and start is not None:
            snippets.append((start, "\n".join(lines[start : number - 1])))
            start = None
    return snippets


def shrink_training(code: str) -> str:
    """`learn(total_timesteps=100_000)` / `learn(150_000)` -> `SHORT_TRAINING` steps; `PPO("MlpPolicy", env, ...`
    -> `PPO("MlpPolicy", env, n_steps=SHORT_TRAINING, batch_size=SHORT_TRAINING, ...`."""
    code = re.sub(r"\.learn\((total_timesteps=)?[\d_]+", lambda m: f".learn({m.group(1) or ''}{SHORT_TRAINING}", code)
    return re.sub(r"\bPPO\(([^,]+, [^,]+),", rf"PPO(\1, n_steps={SHORT_TRAINING}, batch_size={SHORT_TRAINING},", code)


def test_readme_has_the_snippets_it_should():
    snippets = python_snippets()
    assert len(snippets) >= 6 and any(".learn(" in code for _, code in snippets)
    assert "learn(64" in shrink_training("model.learn(150_000)") and "total_timesteps=64" in shrink_training(".learn(total_timesteps=1_000)")
    assert shrink_training('PPO("MlpPolicy", env, verbose=1)') == 'PPO("MlpPolicy", env, n_steps=64, batch_size=64, verbose=1)'


@pytest.mark.parametrize("line, code", python_snippets(), ids=[f"line{line}" for line, _ in python_snippets()])
def test_readme_snippet_runs_verbatim_from_another_folder(line, code, tmp_path):
    script = tmp_path / "snippet.py"
    script.write_text(shrink_training(code))
    # one torch thread: beside the other pytest worker, two threads each made SB3's 2,048 single-body steps 20x slower
    environment = {**os.environ, "OMP_NUM_THREADS": "1"}
    result = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600,
                            env=environment)  # fmt: skip
    assert result.returncode == 0, f"README.md snippet at line {line} failed:\n{result.stderr[-3000:]}"
