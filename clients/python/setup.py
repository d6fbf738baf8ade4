"""Build hook: compile the service's proto into ``sublevel_client._pb`` with grpcio-tools.

The contract lives in the repository at ``proto/sublevel/v1/`` (``../../proto`` from this file):
``sublevel.proto`` (the service) and one file of messages per domain. Nothing generated is
committed: ``build_py`` runs ``python -m grpc_tools.protoc`` on every build and writes
``sublevel_client/_pb/sublevel/v1/*_pb2{,_grpc}.py{,i}``

* into the build directory for a regular install (``pip install ./clients/python``), and
* into ``src/sublevel_client/_pb`` for an editable install (``pip install -e ./clients/python``).

protoc emits absolute imports (``from sublevel.v1 import sublevel_pb2``); they are rewritten to
``from sublevel_client._pb.sublevel.v1 import sublevel_pb2`` so nothing named ``sublevel`` has to be
importable at top level. An sdist carries a copy of the proto (``proto/`` beside this file), which
is preferred when present. ``SUBLEVEL_PROTO_DIR`` overrides both.
"""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py as _build_py
from setuptools.command.sdist import sdist as _sdist

HERE = Path(__file__).resolve().parent
# The service's file first (it imports the others publicly, so ``sublevel_pb2`` names every message).
PROTO_FILES = [
    "sublevel/v1/sublevel.proto",
    "sublevel/v1/geometry.proto",
    "sublevel/v1/bodies.proto",
    "sublevel/v1/scenes.proto",
    "sublevel/v1/queries.proto",
    "sublevel/v1/robots.proto",
    "sublevel/v1/planning.proto",
]
PB_PACKAGE = "sublevel_client._pb"


def proto_root() -> Path:
    """The directory holding ``sublevel/v1/sublevel.proto``."""
    candidates = []
    if os.environ.get("SUBLEVEL_PROTO_DIR"):
        candidates.append(Path(os.environ["SUBLEVEL_PROTO_DIR"]))
    candidates += [HERE / "proto", HERE.parent.parent / "proto"]
    for c in candidates:
        if all((c / f).is_file() for f in PROTO_FILES):
            return c.resolve()
    raise RuntimeError(
        "sublevel_client: cannot find %s in any of %s (build from the repository checkout, "
        "or set SUBLEVEL_PROTO_DIR)" % (PROTO_FILES[0], ", ".join(map(str, candidates)))
    )


def generate(out_pkg_dir: Path) -> None:
    """Compile the protos into ``out_pkg_dir`` (the ``sublevel_client/_pb`` directory)."""
    root = proto_root()
    out_pkg_dir = Path(out_pkg_dir).resolve()
    if out_pkg_dir.exists():
        shutil.rmtree(out_pkg_dir)
    out_pkg_dir.mkdir(parents=True)
    cmd = [
        sys.executable, "-m", "grpc_tools.protoc",
        "-I", str(root),
        "--python_out=" + str(out_pkg_dir),
        "--pyi_out=" + str(out_pkg_dir),
        "--grpc_python_out=" + str(out_pkg_dir),
    ] + PROTO_FILES
    print("sublevel_client: " + " ".join(cmd), file=sys.stderr)
    subprocess.check_call(cmd, cwd=str(root))
    (out_pkg_dir / "__init__.py").write_text(
        '"""gRPC stubs generated from proto/ by grpcio-tools at build time (do not edit)."""\n'
    )
    # Package markers for every generated directory, and absolute imports made package-relative.
    for d in sorted(p for p in out_pkg_dir.rglob("*") if p.is_dir()):
        init = d / "__init__.py"
        if not init.exists():
            init.write_text("")
    pattern = re.compile(r"^(\s*)from (sublevel(?:\.\w+)*) import ", re.M)
    for f in out_pkg_dir.rglob("*.py*"):
        text = f.read_text()
        fixed = pattern.sub(lambda m: "%sfrom %s.%s import " % (m.group(1), PB_PACKAGE, m.group(2)), text)
        if fixed != text:
            f.write_text(fixed)


class build_py(_build_py):
    """Runs the regular build_py, then generates the stubs."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            target = HERE / "src" / "sublevel_client" / "_pb"
        else:
            target = Path(self.build_lib) / "sublevel_client" / "_pb"
        generate(target)


class sdist(_sdist):
    """Ships a copy of the proto, so a build from the sdist finds it beside setup.py."""

    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        root = proto_root()
        for f in PROTO_FILES:
            dst = Path(base_dir) / "proto" / f
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(root / f, dst)


setup(cmdclass={"build_py": build_py, "sdist": sdist})
