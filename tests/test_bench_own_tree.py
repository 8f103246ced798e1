"""A benchmark run as ``python benchmarks/X.py`` from another checkout (a clean clone of an
older revision, to compare against) must time that checkout's code, not the editable install's:
the script's directory, not the repository root, is what Python puts on ``sys.path``, and the
editable install's finder then resolves ``sensornet`` to the installed tree."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GUARD = "sys.path.insert(0, str(Path(__file__).resolve().parents[1]))"
IMPORT = re.compile(r"^\s*(from sensornet[\w.]* import|import sensornet)", re.M)


def test_every_benchmark_puts_its_own_checkout_first():
    """Each script that imports ``sensornet`` puts its checkout's root (or, in the scripts that
    time other revisions, that revision's folder) first on ``sys.path`` before the first such
    import."""
    late = []
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        text = path.read_text()
        first = IMPORT.search(text)
        if first is None:
            continue
        guard = re.search(r"sys\.path\.insert\(0, ", text)  # the root, or a revision's
        if guard is None or guard.start() > first.start():
            late.append(path.name)
    assert not late, f"benchmarks importing sensornet before their own checkout: {late}"


def test_the_guard_beats_the_installed_package(tmp_path):
    """The mechanism: a copy of a checkout with its own ``sensornet`` package; its script with
    the guard imports the copy's package even though the venv's editable install maps
    ``sensornet`` to this repository."""
    (tmp_path / "sensornet").mkdir()
    (tmp_path / "sensornet" / "__init__.py").write_text("WHERE = 'copy'\n")
    (tmp_path / "benchmarks").mkdir()
    script = tmp_path / "benchmarks" / "probe.py"
    script.write_text("import sys\nfrom pathlib import Path\n\nif not __package__:\n"
                      f"    {GUARD}\n\nimport sensornet\n\nprint(sensornet.__file__)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=60, cwd=tmp_path, check=True).stdout.strip()
    assert Path(out) == tmp_path / "sensornet" / "__init__.py"
    without = script.read_text().replace(GUARD, "pass")
    script.write_text(without)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         timeout=60, cwd=tmp_path, check=True).stdout.strip()
    assert Path(out) != tmp_path / "sensornet" / "__init__.py"  # why the guard is needed
