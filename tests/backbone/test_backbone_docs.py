"""The references a newcomer reads stay current: benchmarks/RESULTS.md is what the benchmarks' figures
files give, docs/ARCHITECTURE.md stays a short reference, and its decision records exist."""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DECISIONS = ROOT / "docs" / "decisions"


def test_results_md_is_generated_from_the_figures_files():
    run = subprocess.run([sys.executable, "-m", "benchmarks.report", "--check"], cwd=ROOT, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stderr


def test_architecture_is_a_short_reference():
    lines = (ROOT / "docs" / "ARCHITECTURE.md").read_text().splitlines()
    assert len(lines) <= 300, "docs/ARCHITECTURE.md is a reference of at most 300 lines; move detail to docs/decisions"


def test_decision_records_have_their_sections_and_every_link_resolves():
    records = sorted(DECISIONS.glob("[0-9][0-9][0-9][0-9]-*.md"))
    assert records
    for record in records:
        text = record.read_text()
        for section in ("## Context", "## Decision", "## Alternatives", "## Consequences"):
            assert section in text, f"{record.name} lacks its '{section}' section"
    for doc in [ROOT / "docs" / "ARCHITECTURE.md", ROOT / "README.md", DECISIONS / "README.md", *records]:
        for name in re.findall(r"\b(\d{4}-[a-z0-9-]+\.md)", doc.read_text()):
            assert (DECISIONS / name).exists(), f"{doc.name} names docs/decisions/{name}, which does not exist"


def test_the_commit_msg_hook_refuses_subjects_over_72_characters(tmp_path):
    hook = ROOT / ".githooks" / "commit-msg"
    for subject, refused in [("s" * 72, False), ("s" * 73, True)]:
        message = tmp_path / "message"
        message.write_text(f"{subject}\n\nA body of any length, " + "long " * 40 + "\n")
        run = subprocess.run([str(hook), str(message)], capture_output=True, text=True)
        assert (run.returncode != 0) == refused, (len(subject), run.stderr)
