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


def replace_rows(path: Path, rows: dict[str, str], insert_before: str, note: str) -> None:
    """Rewrite the markdown table rows of `path` whose first cell is a key of `rows` ({label: whole row line});
    a label not yet in the table goes after the row before it in `rows`, or else before the first line starting
    with `insert_before`. `note` is added as a line after the table's header paragraph (what was rerun, where).
    Atomic."""
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist: run the whole benchmark once before rerunning rows")
    lines = path.read_text().split("\n")
    previous = None
    for label, row in rows.items():
        found = [i for i, line in enumerate(lines) if line.startswith(f"| {label} |")]
        if found:
            lines[found[0]] = row
        elif previous is not None:
            lines.insert(lines.index(previous) + 1, row)
        else:
            lines.insert(next(i for i, line in enumerate(lines) if line.startswith(insert_before)), row)
        previous = row
    table = next(i for i, line in enumerate(lines) if line.startswith("|"))
    lines.insert(table - 1, note)
    atomic_write(path, lambda file: file.write("\n".join(lines).encode()))
