"""scripts/check_api_stubs.py, the static check of the add-on against the API stubs of a newer Blender:
on a small stub tree written here it finds each kind of problem it is there for, and nothing in code that
uses the API as the stubs define it. (`.ci/run` runs it on the add-on against the newest stubs.)"""

from __future__ import annotations

import importlib.util
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def checker():
    spec = importlib.util.spec_from_file_location("check_api_stubs", REPO / "scripts" / "check_api_stubs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def stub_tree(root: Path) -> Path:
    files = {
        "bpy-stubs/types/__init__.pyi": """
            class bpy_struct[_T]:
                def as_pointer(self) -> int: ...
            class Operator(bpy_struct):
                bl_idname: str
                bl_label: str
                bl_options: set[str]
            class Context(bpy_struct):
                scene: object
                active_object: object
            type Alias = int
            """,
        "bl_ui-stubs/space_view3d/__init__.pyi": "class VIEW3D_MT_pose: ...\n",
        "bpy-stubs/stub_internal/rna_enums/__init__.pyi":
            'import typing\ntype IconItems = typing.Literal["NONE", "ACTION"]\n',
        "bpy-stubs/ops/import_anim/__init__.pyi": """
            class bvh:
                def __new__(cls, execution_context=None, /, *, filepath: str = "", global_scale: float = 1.0): ...
            """,
        "bpy-stubs/props/__init__.pyi": "def IntProperty(): ...\n",
        "bpy-stubs/utils/__init__.pyi": "def register_class(cls): ...\n",
        "bpy-stubs/app/__init__.pyi": "version: tuple\n",
        "bpy-stubs/path/__init__.pyi": "def abspath(p): ...\n",
        "bpy_extras-stubs/anim_utils/__init__.pyi": "def action_get_channelbag_for_slot(a, s): ...\n",
        "mathutils-stubs/__init__.pyi": "class Matrix: ...\n",
    }
    for rel, text in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(textwrap.dedent(text))
    return root


def test_the_check_finds_each_kind_of_problem_and_passes_good_code(tmp_path):
    module = checker()
    stubs = module.Stubs(stub_tree(tmp_path / "stubs"))
    good = tmp_path / "good.py"
    good.write_text(textwrap.dedent("""
        import bpy
        class STRNN_OT_x(bpy.types.Operator):
            bl_idname = "strnn.x"
            bl_options = {"REGISTER"}
            def execute(self, context):
                bpy.ops.import_anim.bvh(filepath="a.bvh", global_scale=2.0)
                self.layout.operator("strnn.x", icon="ACTION")
                print(context.scene, bpy.context.active_object, bpy.app.version, bpy.props.IntProperty)
                return {"FINISHED"}
        """))
    assert module.check_file(good, stubs) == []
    bad = tmp_path / "bad.py"
    bad.write_text(textwrap.dedent("""
        import bpy
        class STRNN_OT_y(bpy.types.Operator):
            bl_idname = "strnn.y"
            bl_undo_group = "x"
            def execute(self, context):
                bpy.ops.import_anim.bvh(filepath="a.bvh", use_fps_scale=True)
                bpy.ops.import_anim.fbx(filepath="a.fbx")
                self.layout.label(text="x", icon="NOT_AN_ICON")
                print(context.screen_area, bpy.types.Panel, bpy.utils.gone)
        """))
    found = "\n".join(module.check_file(bad, stubs))
    for problem in ("Operator has no setting 'bl_undo_group'", "takes no keyword 'use_fps_scale'",
                    "operator bpy.ops.import_anim.fbx is not in the API", "icon 'NOT_AN_ICON' is not in the API",
                    "Context has no member 'screen_area'", "bpy.types.Panel is not in the API",
                    "bpy.utils.gone is not in the API"):
        assert problem in found, problem
