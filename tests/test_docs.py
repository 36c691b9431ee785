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


def guide_commands() -> list[str]:
    """The shell commands of README's guides, as a user would paste them (templates that need
    the user's own deployment or cameras left out)."""
    import re

    text = (ROOT / "README.md").read_text(encoding="utf-8")
    guides = text[text.index("## Guides"):text.index("## Accuracy and speed")]
    cmds = []
    for block in re.findall(r"```bash\n(.*?)```", guides, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            line = line.split("  #")[0].strip()
            templates = ("deployment.yaml", "http", "/dev/video")
            if line and not line.startswith("#") and not any(t in line for t in templates):
                cmds.append(line)
    return cmds


def test_readme_guide_commands_work_as_written(tmp_path):
    """Each guide command, pasted in order into a shell in a fresh folder holding the
    examples, succeeds."""
    import os
    import subprocess
    import sys

    for name in ("layouts", "surveys"):
        (tmp_path / name).symlink_to(ROOT / name)
    cmds = guide_commands()
    assert len(cmds) >= 8 and any(c.startswith("vlpcal import") for c in cmds)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    for cmd in cmds:
        res = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, env=env,
                             capture_output=True, text=True)
        assert res.returncode == 0, (cmd, res.stdout[-500:], res.stderr[-500:])
