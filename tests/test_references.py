"""Every file the code, the README and the design notes refer to ships with the repository."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("demcal", "measure", "simulate", "analyse", "report", "benchmarks", "data", "tests", "docs")
#: A path into one of the repository's folders, e.g. docs/design.md or data/paper_defaults.json.
REPO_PATH = re.compile(r"(?<![\w./-])((?:%s)/[\w./-]*\w\.[a-z]{2,4})\b" % "|".join(FOLDERS))
#: A document named without its folder, e.g. README.md.
DOCUMENT = re.compile(r"(?<![\w./-])([\w-]+\.md)\b")


def _texts():
    for folder in FOLDERS:
        for path in (ROOT / folder).rglob("*"):
            if path.suffix in (".py", ".md", ".j2") and "__pycache__" not in path.parts:
                yield path
    yield ROOT / "README.md"


def test_every_referred_file_exists():
    missing = []
    for path in _texts():
        text = path.read_text(encoding="utf-8")
        for m in REPO_PATH.finditer(text):
            if not (ROOT / m.group(1)).exists():
                missing.append(f"{path.relative_to(ROOT)}: {m.group(1)}")
        for m in DOCUMENT.finditer(text):
            name = m.group(1)
            if not any((d / name).exists() for d in (ROOT, ROOT / "docs", path.parent)):
                missing.append(f"{path.relative_to(ROOT)}: {name}")
    assert not missing, "references to files not in the repository:\n" + "\n".join(missing)
