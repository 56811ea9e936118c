"""The OpenDRIVE export passes ASAM's Quality Checker (``asam-qc-opendrive``): its XML
and schema checks and the semantic and geometry checks that apply to OpenDRIVE 1.6.
The checkers and how the tests find them: :mod:`tests.asam_qc`."""

from mapgen.opendrive import write_opendrive
from tests.asam_qc import ERROR, WARNING, issues, run_checker


def test_the_opendrive_export_passes_the_asam_quality_checker(built_map, tmp_path):
    xodr = write_opendrive(built_map, tmp_path / "i24.xodr")
    report = run_checker("qc_opendrive", "xodrBundle", xodr, tmp_path)
    assert issues(report, ERROR) == []
    assert issues(report, WARNING) == []
    status = {c.get("checkerId"): c.get("status") for c in report.iter("Checker")}
    # the XML and schema checks ran (the others apply to OpenDRIVE 1.7 and later, or to
    # junctions and lane sections the segment does not have)
    for checker in ("valid_xml_document", "root_tag_is_opendrive", "fileheader_is_present",
                    "version_is_defined", "valid_schema"):  # fmt: skip
        assert status[f"check_asam_xodr_xml_{checker}"] == "completed"
