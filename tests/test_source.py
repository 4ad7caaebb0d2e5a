"""The source holds no dead names: every module-level function, class and constant of the package is used
somewhere (the package, the experiments, the tests) or documented (README, docs/); and the docs no dead links to a
section. Pure Python."""

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_module_level_name_is_used_or_documented():
    code = {p: p.read_text() for p in [*ROOT.glob("hopper_mjx/**/*.py"), *ROOT.glob("experiments/*.py"),
                                       *ROOT.glob("tests/*.py")]}
    uses = {}
    for text in code.values():
        for word in re.findall(r"\w+", text):
            uses[word] = uses.get(word, 0) + 1
    documented = set(re.findall(r"\w+", " ".join(p.read_text() for p in [ROOT / "README.md", *ROOT.glob("docs/*.md")])))
    dead = []
    for path in sorted(ROOT.glob("hopper_mjx/**/*.py")):
        for node in ast.parse(code[path]).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                names = [node.name]
            elif isinstance(node, ast.Assign):
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
            else:
                continue
            dead += [f"{path.relative_to(ROOT)}:{node.lineno} {name}" for name in names
                     if uses.get(name, 0) <= 1 and name not in documented and not name.startswith("__")]
    assert not dead, "defined, never used:\n" + "\n".join(dead)


MAX_FUNCTION_LINES = 80


def test_functions_are_at_most_80_lines():
    long = []
    for path in sorted([*ROOT.glob("hopper_mjx/**/*.py"), *ROOT.glob("experiments/*.py")]):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}: {lines} lines")
    assert not long, "\n".join(long)


def test_the_longest_first_order_names_test_files_that_exist():
    """conftest.LONGEST_FIRST is a measured order; a renamed or removed file would drop out of it silently."""
    from conftest import LONGEST_FIRST

    missing = [name for name in LONGEST_FIRST if not (ROOT / "tests" / name).is_file()]
    assert not missing and len(set(LONGEST_FIRST)) == len(LONGEST_FIRST), missing


def heading_anchor(heading: str) -> str:
    """The anchor GitHub gives a Markdown heading: lower case, punctuation but `-` and `_` dropped, spaces as `-`."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_every_link_to_a_section_of_the_docs_finds_its_heading():
    """A link `page.md#section` (or `#section` on its own page) in the README and docs/ names a heading that exists:
    a heading renamed with its code (a module moved into a package) must take its links along."""
    pages = [ROOT / "README.md", *sorted(ROOT.glob("docs/*.md"))]
    anchors = {p.resolve(): {heading_anchor(h) for h in re.findall(r"^#+ (.*)$", p.read_text(), re.M)} for p in pages}
    broken = []
    for page in pages:
        for target, anchor in re.findall(r"\]\(([^)#\s]*\.md)?#([^)\s]+)\)", page.read_text()):
            linked = (page.parent / target).resolve() if target else page.resolve()
            if linked in anchors and anchor not in anchors[linked]:
                broken.append(f"{page.relative_to(ROOT)}: {target}#{anchor}")
    assert not broken, "links to no heading:\n" + "\n".join(broken)


def test_the_readmes_speed_line_gives_the_performance_pages_figures():
    """README's "Where it stands" speed line quotes the ratios of docs/performance.md's summary table (N = 4096, N =
    64, rough ground), so that a new measurement on that page cannot leave the README behind (it once said 7.35x and
    1.90x beside the page's 8.20x and 1.56x)."""
    summary = (ROOT / "docs" / "performance.md").read_text().split("## The levers", 1)[0]
    rows = re.findall(r"^\| `(--num \d+)[^`]*` \|(?:[^|]*\|){2} ([\d.]+) \|", summary, re.M)
    assert [flag for flag, _ in rows] == ["--num 4096", "--num 64", "--num 4096"], rows  # flat, small, rough
    speed = re.search(r"^- \*\*Speed\.\*\* (.*?)(?=^- )", (ROOT / "README.md").read_text(), re.M | re.S).group(1)
    quoted = re.findall(r"([\d.]+)× ", speed)
    assert quoted == [ratio for _, ratio in rows], (quoted, rows)
