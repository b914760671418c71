"""Result files with one `## ` section per benchmark, each rewritten on its own."""

from __future__ import annotations

from pathlib import Path

from motion_envs.atomic import atomic_write


def replace_section(path: Path, section: str, title: str = "# Throughput") -> None:
    """Write `section` (starting with its `## ` heading line) into `path`, replacing the section of the same
    heading if there is one, else appending it; other sections stay. Atomic."""
    heading = section.split("\n", 1)[0]
    text = path.read_text() if path.exists() else f"{title}\n\n"
    if heading in text:
        before, _, after = text.partition(heading)
        following = after.find("\n## ")
        text = before + section + (after[following + 1 :] if following >= 0 else "")
    else:
        text = text.rstrip() + "\n\n" + section
    atomic_write(path, lambda file: file.write(text.encode()))
