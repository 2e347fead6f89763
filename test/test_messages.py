"""The interface package: it builds from source, every message imports, serialises and travels."""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from conftest import REPO
from rosutil import spin_until

MSG_DIR = REPO / "src" / "ins_gnss_msgs" / "msg"
MESSAGES = sorted(p.stem for p in MSG_DIR.glob("*.msg"))


def _message_class(name: str):
    return getattr(importlib.import_module("ins_gnss_msgs.msg"), name)


def _filled(cls):
    """An instance with every field set to a non-default value, recursively."""
    msg = cls()
    for field, ftype in cls.get_fields_and_field_types().items():
        value = getattr(msg, field)
        if ftype in ("double", "float"):
            setattr(msg, field, 1.25)
        elif ftype.startswith(("uint", "int", "octet")) and "[" not in ftype and "<" not in ftype:
            setattr(msg, field, 3)
        elif ftype == "boolean":
            setattr(msg, field, True)
        elif ftype == "string":
            setattr(msg, field, "x")
        elif ftype.startswith("sequence<double") or ftype.startswith("sequence<float"):
            setattr(msg, field, [1.5, -2.5])
        elif ftype.startswith("sequence<boolean"):
            setattr(msg, field, [True, False])
        elif ftype.startswith("sequence<string"):
            setattr(msg, field, ["a", "b"])
        elif ftype.startswith("sequence<") and "/" in ftype:   # of messages of any package
            package, name = ftype[len("sequence<"):].rstrip(">").split("/")
            inner = getattr(importlib.import_module(f"{package}.msg"), name)
            setattr(msg, field, [_filled(inner)])
        elif ftype.startswith("sequence<"):
            setattr(msg, field, [1, 2])
        elif ftype.startswith("double[") or ftype.startswith("float["):
            value[:] = 0.5
        elif hasattr(value, "get_fields_and_field_types"):
            setattr(msg, field, _filled(type(value)))
    return msg


def test_every_message_is_declared_in_cmake():
    cmake = (REPO / "src" / "ins_gnss_msgs" / "CMakeLists.txt").read_text()
    assert MESSAGES, "no .msg files found"
    for name in MESSAGES:
        assert f'"msg/{name}.msg"' in cmake


@pytest.mark.parametrize("name", MESSAGES)
def test_message_round_trips_through_serialization(name):
    cls = _message_class(name)
    msg = _filled(cls)
    back = deserialize_message(serialize_message(msg), cls)
    assert back == msg
    assert back != cls() or not cls.get_fields_and_field_types()


@pytest.mark.slow
def test_the_mode_constants_of_state_correction_and_status_agree():
    """The strapdown says the mode the ekf sends in InsCorrection and reports in FilterStatus
    (nodes/convert.py MODE_VALUES maps all three)."""
    modes = {name: [(k, v) for k, v in vars(_message_class(name)).items()
                    if k.startswith("MODE_")]
             for name in ("InsState", "InsCorrection", "FilterStatus")}
    assert modes["InsState"] == modes["FilterStatus"]
    assert modes["InsCorrection"] == modes["InsState"][:3]  # a filter never sends INVALID


def test_interface_package_builds_from_source(tmp_path):
    """Configure, build and install src/ins_gnss_msgs with CMake against the venv's ROS wheels."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    prefix = Path(sys.prefix)
    env = dict(os.environ, AMENT_PREFIX_PATH=str(prefix), CMAKE_PREFIX_PATH=str(prefix),
               PATH=f"{prefix / 'bin'}:{os.environ['PATH']}")
    build, install = tmp_path / "build", tmp_path / "install"
    for cmd in (
        ["cmake", "-S", str(REPO / "src" / "ins_gnss_msgs"), "-B", str(build),
         f"-DCMAKE_INSTALL_PREFIX={install}", f"-DPython3_EXECUTABLE={sys.executable}"],
        ["cmake", "--build", str(build), "-j2"],
        ["cmake", "--install", str(build)],
    ):
        done = subprocess.run(cmd, env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    generated = install / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / \
        "site-packages" / "ins_gnss_msgs" / "msg"
    for name in MESSAGES:
        snake = "".join("_" + c.lower() if c.isupper() else c for c in name).lstrip("_")
        assert (generated / f"_{snake}.py").is_file(), name


PUBLISHER = textwrap.dedent(
    """
    import rclpy, sys
    from rclpy.node import Node
    from ins_gnss_msgs.msg import InsState
    rclpy.init()
    node = Node("remote_publisher")
    pub = node.create_publisher(InsState, "ins/state", 10)
    msg = InsState(latitude=1.0471975511965976, longitude=0.5, altitude=12.5, mode=InsState.MODE_NAVIGATING)
    msg.orientation.w = 1.0
    while rclpy.ok():
        if pub.get_subscription_count() > 0:
            pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.1)
    """
)


def test_message_travels_between_processes(executor, probe):
    from ins_gnss_msgs.msg import InsState

    received: list[InsState] = []
    probe.create_subscription(InsState, "ins/state", received.append, 10)
    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER], env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        spin_until(executor, lambda: bool(received) or proc.poll() is not None, 30, "InsState")
        assert received, proc.stdout.read().decode()
    finally:
        proc.terminate()
        proc.wait(10)
    msg = received[0]
    assert (msg.latitude, msg.longitude, msg.altitude) == (1.0471975511965976, 0.5, 12.5)
    assert msg.mode == InsState.MODE_NAVIGATING
