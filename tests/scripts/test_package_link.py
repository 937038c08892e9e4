# SPDX-License-Identifier: GPL-3.0-or-later
"""scripts/package_link.py imports the checkout as ``curved_reflections``, without bpy.

Each case runs in a fresh Python so that its ``sys.modules`` starts empty.
"""

import subprocess
import sys
import textwrap


def run_python(repo_root, code):
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=repo_root / "scripts", capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


def test_imports_the_checkout_as_the_package_without_bpy(repo_root):
    out = run_python(repo_root, f"""
        import sys
        from pathlib import Path
        from package_link import import_as_package

        package = import_as_package({str(repo_root)!r})
        import curved_reflections.engine
        from curved_reflections.engine import Reflector
        assert package.__name__ == "curved_reflections"
        assert Path(package.__path__[0]).resolve() == Path({str(repo_root)!r}).resolve()
        assert Path(package.__path__[0]).name == "curved_reflections"
        assert import_as_package({str(repo_root)!r}) is package
        print("bpy" in sys.modules)
    """)
    assert out.strip() == "False"


def test_refuses_a_second_checkout_under_the_same_name(repo_root, tmp_path):
    other = tmp_path / "other_checkout"
    other.mkdir()
    (other / "__init__.py").write_text("")
    run_python(repo_root, f"""
        from package_link import import_as_package

        import_as_package({str(repo_root)!r})
        try:
            import_as_package({str(other)!r})
        except ImportError as error:
            assert "already imported" in str(error)
        else:
            raise AssertionError("a second checkout replaced the first")
    """)
