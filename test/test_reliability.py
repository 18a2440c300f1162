"""The fault-injection campaign's CI subset (``make reliability QUICK=1``): every category runs
the same code as ``make reliability`` with smaller counts, and every case must pass."""
import pytest

pytest.importorskip("rclpy")
pytest.importorskip("hypothesis")

from reliability import campaign as rel  # noqa: E402


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("reliability")


@pytest.mark.parametrize("category", list(rel.CATEGORIES))
def test_campaign_category(category, workdir):
    rows = rel.CATEGORIES[category](rel.QUICK, workdir)
    print("\n" + rel.format_table(rows))
    for row in rows:
        real = [f for f in row.failures if not f.startswith("(info)")]
        assert row.tried > 0, f"{row.category}: nothing tried"
        assert row.passed == row.tried, f"{row.category}: {real}"


def test_generated_bad_inputs_meet_the_issue_count():
    # the full campaign generates at least 1000 bad numeric inputs (make reliability)
    assert rel.FULL.bad_inputs >= 1000 and rel.FULL.burst == 200 and rel.FULL.sustained_s >= 60
