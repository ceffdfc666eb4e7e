"""The documentation says what the repository does: the README's set-up commands are the ones
CI runs, every file the source and the docs cite exists, and the source cites documents of the
repository, not a tracker's issue numbers or a design page outside it.

Read from the files only (nothing imported, nothing run)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / ".ci" / "run"

#: where citations are looked for: the source, tests, benchmarks, examples and every document
CITING = [*sorted((ROOT / "src").rglob("*.py")), *sorted((ROOT / "tests").rglob("*.py")),
          *sorted((ROOT / "benchmarks").rglob("*.py")), *sorted((ROOT / "examples").rglob("*.py")),
          *sorted((ROOT / "examples").rglob("*.toml")), ROOT / "README.md",
          *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "benchmarks").rglob("*.md"))]
#: a repository path: one of the top folders, then a file name with an extension
REPO_PATH = re.compile(r"(?<![\w./-])((?:docs|tests|benchmarks|examples|mandrels|src)/[\w./*-]*\.(?:md|py|toml|stl|csv))")
#: a relative Markdown link target
MD_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def _bash_blocks(text: str) -> list[str]:
    return re.findall(r"```bash\n(.*?)```", text, flags=re.S)


def _ci_commands() -> list[str]:
    lines = [line.strip() for line in CI.read_text(encoding="utf-8").splitlines()]
    return [line for line in lines if line and not line.startswith("#")]


def test_the_readme_opens_with_the_set_up_commands_ci_runs():
    blocks = _bash_blocks((ROOT / "README.md").read_text(encoding="utf-8"))
    run, tests = (block.strip().split(" && ") for block in blocks[:2])
    ci = _ci_commands()
    # the same three set-up steps: a venv, activated, the package installed with its test extra
    for steps in (run, tests):
        assert steps[0].startswith("python3 -m venv ") and any(c.startswith("python3 -m venv ") for c in ci)
        venv = steps[0].split()[-1]
        assert steps[1] == f". {venv}/bin/activate"
        install = shlex.split(steps[2])
        assert install[:2] == ["pip", "install"]
        ci_install = next(shlex.split(c) for c in ci if "pip install" in c and "--upgrade" not in c)
        assert [a for a in install[2:] if a != "-q"] == [a for a in ci_install[4:] if a != "-q"]
    # the first command runs the flagship example, the second the tests exactly as CI does
    assert run[3] == "preform run examples/case_a.toml" and (ROOT / "examples" / "case_a.toml").is_file()
    assert tests[3] == "python -m pytest -q" == ci[-1]


def _cited_paths():
    for path in CITING:
        text = path.read_text(encoding="utf-8")
        for match in REPO_PATH.finditer(text):
            # code also names files it makes up (a test's "mandrels/x.stl"): there only the
            # documents and test modules it cites count
            if path.suffix != ".py" or match.group(1).startswith(("docs/", "tests/")):
                yield path, match.group(1)
        if path.suffix == ".md":
            for target in MD_LINK.findall(text):
                if "://" not in target and not target.startswith("mailto:"):
                    yield path, str((path.parent / target).resolve().relative_to(ROOT))


def test_every_cited_repository_path_exists():
    missing = set()
    for source, cited in _cited_paths():
        cited = cited.rstrip(".")
        if cited.startswith("examples/results/"):
            continue        # what running an example writes (git-ignored), not a shipped file
        found = list(ROOT.glob(cited)) if "*" in cited else [ROOT / cited]
        if not found or not all(p.exists() for p in found):
            missing.add(f"{source.relative_to(ROOT)}: {cited}")
    assert not missing, "\n".join(sorted(missing))


@pytest.mark.parametrize("pattern,what", [
    (r"\bissues? \d+", "an issue number"),
    (r"DESIGN\.md", "DESIGN.md (the design is docs/architecture.md)"),
])
def test_the_source_cites_documents_of_the_repository(pattern, what):
    citing = [p for p in CITING if p.suffix == ".py" and ROOT / "src" in p.parents]
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}"
             for p in citing for n, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
             if re.search(pattern, line)]
    assert not found, f"{what} cited in the source:\n" + "\n".join(found)


def test_cited_sections_exist():
    """``docs/architecture.md §N`` and ``docs/theory.md §N`` name a section of that page."""
    pages = {"architecture.md": r"^## §(\d+) ", "theory.md": r"^## (\d+)\. "}
    for page, heading in pages.items():
        sections = set(re.findall(heading, (ROOT / "docs" / page).read_text(encoding="utf-8"), flags=re.M))
        cited = {}
        for p in CITING:
            for number in re.findall(re.escape(page) + r",? §(\d+)", p.read_text(encoding="utf-8")):
                cited.setdefault(number, p.relative_to(ROOT))
        unknown = {n: str(p) for n, p in cited.items() if n not in sections}
        assert not unknown, f"{page}: sections cited but absent: {unknown}"


def test_the_configuration_reference_names_every_key():
    from preform.config import GUIDE_RING_KEYS, KEYS, LAYER_KEYS

    page = (ROOT / "docs" / "guide" / "configuration.md").read_text(encoding="utf-8")
    for section, keys in KEYS.items():
        assert f"`[{section}]`" in page, section
        for key in keys:
            assert f"| `{key}` |" in page, f"[{section}] {key}"
    for key in (*GUIDE_RING_KEYS, *LAYER_KEYS):
        assert f"`{key}" in page or f"{key} =" in page, key


def _github_anchor(title: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation but ``-`` and ``_`` dropped,
    spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")


def test_the_decisions_index_links_every_record_once():
    """``docs/decisions.md`` opens with an index by topic: every record (a ``###`` heading)
    appears in it exactly once, linked to its heading's anchor, and it links to nothing else."""
    text = (ROOT / "docs" / "decisions.md").read_text(encoding="utf-8")
    start = text.index("\n## Index\n")
    index = text[start:text.index("\n## ", start + 1)]
    records = re.findall(r"^### (.+)$", text, flags=re.M)
    links = re.findall(r"^  - \[(.+)\]\(#([\w-]+)\)$", index, flags=re.M)   # one a line
    assert len(links) == index.count("](#")
    assert sorted(title for title, _ in links) == sorted(records)
    assert all(anchor == _github_anchor(title) for title, anchor in links)
