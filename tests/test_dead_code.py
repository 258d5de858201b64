"""No dead code in ``baker``: ``vulture`` finds nothing the package never uses, at 60 %
confidence (functions, methods, classes, attributes, variables), besides what
``tests/vulture_whitelist.py`` names and says why. A function only the tests call either earns
a place in the API (documented, and named in the whitelist as what a user reads) or goes, its
tests moved to what the code uses."""

from __future__ import annotations

from pathlib import Path

import vulture

ROOT = Path(__file__).resolve().parents[1]


def unused(paths: list[Path]) -> list[str]:
    """What vulture finds unused in ``paths``, one line each (file:line: message)."""
    found = vulture.Vulture()
    found.scavenge([str(path) for path in paths])
    return [f"{Path(item.filename).relative_to(ROOT)}:{item.first_lineno}: {item.message} "
            f"({item.confidence}% confidence)"
            for item in found.get_unused_code(min_confidence=60)]


def test_the_package_has_no_dead_code():
    assert unused([ROOT / "baker", ROOT / "tests" / "vulture_whitelist.py"]) == []


def test_the_check_finds_a_function_nothing_calls(tmp_path):
    module = tmp_path / "m.py"
    module.write_text("def used():\n    return 1\n\n\ndef forgotten():\n    return 2\n\n\n"
                      "print(used())\n")
    global ROOT
    saved, ROOT = ROOT, tmp_path
    try:
        assert unused([module]) == ["m.py:5: unused function 'forgotten' (60% confidence)"]
    finally:
        ROOT = saved
