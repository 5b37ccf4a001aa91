"""The README's scripting example runs as written on an armature named "Armature"."""

from __future__ import annotations

import re

from scenes import REPO, import_bvh, walk_bvh


def test_readme_script_runs(addon, tmp_path, real_model):
    text = (REPO / "README.md").read_text()
    section = text.split("### Scripting", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S)[1]
    obj = import_bvh(walk_bvh(tmp_path, frames=120))
    obj.name = "Armature"
    original = obj.animation_data.action
    exec(compile(code, "README.md (Scripting)", "exec"), {})
    final = obj.animation_data.action
    assert final is not original and original.use_fake_user
    assert final["strnn"]["operation"] == "Foot Lock"
    assert final.frame_range[1] >= 160  # 120 + 120 frames, then the motion after frame 100 redone with 60
