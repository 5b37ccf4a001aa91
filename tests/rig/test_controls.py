"""The shipped control presets (no Blender): which rigs they fit and how they spell the bones."""

from __future__ import annotations

from test_bonemap import _auto_rig_pro

from model_core.rig.controls import preset_for


def test_auto_rig_pro_fits_with_three_or_two_spine_bones():
    three = preset_for(_auto_rig_pro(3)[0])
    two = preset_for(_auto_rig_pro(2)[0])
    assert three.name == two.name == "auto_rig_pro"
    drives = {c.bone: c.drives for c in three.controls}
    assert drives["c_spine_03.x"] == "spine_03.x" and drives["c_thigh_fk.l"] == "thigh.l"
    assert [c.bone for c in three.controls if c.location] == ["c_root_master.x"]  # it alone carries the body
    assert {c.bone for c in three.controls} - {c.bone for c in two.controls} == {"c_spine_03.x"}
    assert {(s.bone, s.prop, s.value) for s in two.switches} == {
        (f"c_{limb}_ik.{s}", "ik_fk_switch", 1.0) for limb in ("foot", "hand") for s in "lr"}


def test_a_rig_without_a_bone_a_preset_needs_gets_no_preset():
    names = [n for n in _auto_rig_pro(3)[0] if n != "c_spine_02.x"]  # only spine_03 and the toes are optional
    assert preset_for(names) is None
    names = [n for n in _auto_rig_pro(3)[0] if n != "c_foot_ik.r"]  # a switch's bone
    assert preset_for(names) is None


def test_auto_rig_pro_without_toes_keys_the_rest():
    names = [n for n in _auto_rig_pro(3)[0] if not n.startswith(("c_toes", "toes"))]
    found = preset_for(names)
    assert found.name == "auto_rig_pro" and len(found.controls) == 20
    assert not any("toes" in c.bone for c in found.controls)
