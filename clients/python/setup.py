"""Generates the gRPC stubs of the ecmxf.v1 API into the package at build
time, from the .proto files of this repository (proto/ecmxf/v1), with the
protoc that grpcio-tools bundles: `pip install ./clients/python` needs no
system protoc and always matches the daemon built from the same tree.

The stubs land in `ecmxf/v1/` (`*_pb2.py`, `*_pb2_grpc.py`, `*.pyi`), which
is where their own absolute imports (`from ecmxf.v1 import common_pb2`)
look for each other.
"""

import os
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent


def proto_root():
    """proto/ of the repository, or $ECMXF_PROTO; a clear error without."""
    root = Path(os.environ.get("ECMXF_PROTO", HERE.parent.parent / "proto"))
    if not (root / "ecmxf" / "v1").is_dir():
        raise SystemExit(
            f"ecmxf: the .proto files are not at {root}/ecmxf/v1: build from the ecmxf repository "
            "(pip install ./clients/python) or set ECMXF_PROTO to its proto/ folder"
        )
    return root


def generate(out):
    from grpc_tools import protoc

    root = proto_root()
    files = sorted(str(p.relative_to(root)) for p in (root / "ecmxf" / "v1").glob("*.proto"))
    include = str(Path(protoc.__file__).parent / "_proto")
    out = str(out)
    args = ["protoc", "-I", str(root), "-I", include, "--python_out", out, "--pyi_out", out, "--grpc_python_out", out]
    if protoc.main(args + files) != 0:
        raise SystemExit("ecmxf: protoc could not compile " + ", ".join(files))
    (Path(out) / "ecmxf" / "v1" / "__init__.py").write_text('"""Generated stubs of the ecmxf.v1 gRPC API."""\n')


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        generate(self.build_lib)


def protobuf_floor():
    """The stubs need a protobuf runtime at least as new as the generator."""
    from google.protobuf import __version__

    major, minor = __version__.split(".")[:2]
    return f"protobuf>={major}.{minor}"


setup(
    cmdclass={"build_py": BuildWithStubs},
    install_requires=["grpcio>=1.66", "grpcio-status>=1.66", protobuf_floor()],
)
