"""Helpers shared by the batch tests (imported by name: tests/ has no packages)."""

from __future__ import annotations

import json
from pathlib import Path

#: good fabrics in the shared library (every 3rd from camera frames), plus broken ones.
#: Four cover each reference family (Sadeghi, Ward, Ashikhmin-Shirley) and the
#: camera-frame input (fabric-003); the tests are about orchestration (skips, retries,
#: kills, timeouts), so each good fabric's fit is the quick KES fit, asked for in the
#: catalogue's kind column (LIBRARY_KIND).
N_GOOD = 4
N_BROKEN = 3
LIBRARY_KIND = "kes"


def manifests(out: Path) -> dict:
    """{(fabric, step): manifest dict} of every committed step under ``out``."""
    found = {}
    for p in sorted(Path(out).glob("*/*/manifest.json")):
        if p.parent.name.startswith("."):  # a scratch folder of a step being computed (pathlib globs dotfiles)
            continue
        found[(p.parent.parent.name, p.parent.name)] = json.loads(p.read_text())
    return found


def leftovers(out: Path) -> list:
    """Scratch folders and step folders without a manifest (half-written results)."""
    bad = [p for p in Path(out).glob("*/.*")]
    bad += [p for p in Path(out).glob("*/*") if p.is_dir() and not p.name.startswith(".")
            and not (p / "manifest.json").is_file()]
    return bad
