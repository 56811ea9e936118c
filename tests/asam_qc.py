"""ASAM's Quality Checkers for the tests: ``qc_opendrive`` (the map's OpenDRIVE,
``tests/mapgen/test_asam_qc.py``) and ``qc_openscenario`` (a run's OpenSCENARIO,
``tests/twin/export/test_openscenario.py``).

The checkers pin numpy below 2, which the twin's stack cannot share, so they live in a
virtual environment of their own: ``.ci/run`` makes it in ``~/.cache/i24-twin-asam`` (or
point ``$ASAM_QC_DIR`` at one). Where it is missing a test is skipped, except under CI,
where it fails."""

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

ERROR, WARNING = "1", "2"  # the checker's issue levels (3 is information)


def _checker(name: str) -> Path | None:
    folders = [os.environ.get("ASAM_QC_DIR"), Path.home() / ".cache" / "i24-twin-asam"]
    for folder in filter(None, folders):
        tool = Path(folder) / "bin" / name
        if tool.is_file():
            return tool
    return None


def run_checker(name: str, bundle: str, document: Path, tmp_path: Path) -> ET.Element:
    """Run the ASAM checker ``name`` (bundle ``bundle``) on ``document``; its report."""
    tool = _checker(name)
    if tool is None:
        if os.environ.get("CI"):
            pytest.fail(f"{name} is not installed; .ci/run installs it into ~/.cache/i24-twin-asam")
        pytest.skip(f"{name} is not installed (python3 -m venv ~/.cache/i24-twin-asam, then "
                    "pip install asam-qc-opendrive asam-qc-openscenarioxml into it)")  # fmt: skip
    report = tmp_path / f"{document.stem}.xqar"
    config = tmp_path / f"{document.stem}.qc.xml"
    config.write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n<Config>\n'
        f'  <Param name="InputFile" value="{document}"/>\n'
        f'  <CheckerBundle application="{bundle}">\n'
        f'    <Param name="resultFile" value="{report}"/>\n'
        "  </CheckerBundle>\n</Config>\n"
    )
    done = subprocess.run([str(tool), "-c", str(config)], capture_output=True, text=True,
                          cwd=tmp_path, timeout=300)  # fmt: skip
    assert done.returncode == 0 and report.is_file(), done.stderr[-2000:]
    return ET.parse(report).getroot()


def issues(report: ET.Element, *levels: str) -> list[str]:
    """The report's issues of ``levels``, each as 'checker: where: what'."""
    return [
        f"{checker.get('checkerId')}: {loc.get('description')}: {issue.get('description')}"
        for checker in report.iter("Checker")
        for issue in checker.iter("Issue")
        if issue.get("level") in levels
        for loc in (issue.findall("Locations") or [issue])
    ]
