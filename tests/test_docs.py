"""docs/formats.md is generated from the JSON Schema that ships with vlpcal: keep it current."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_formats_reference_is_generated_from_the_schema():
    spec = importlib.util.spec_from_file_location("make_formats", ROOT / "docs/make_formats.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    current = (ROOT / "docs/formats.md").read_text(encoding="utf-8")
    assert current == mod.render(), "run: python docs/make_formats.py"
    for key in ("cameras[i].fx", "fusion.region_map[i].cameras", "corrections.<camera id>"):
        assert key in current


def test_readme_links_resolve():
    import re

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#:]+)\)", text):
        assert (ROOT / target).exists(), target
