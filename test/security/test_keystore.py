"""Secured DDS profile: the keystore that security/keystore.sh builds is what the DDS Security
plugins require, checked independently with openssl (certificate chains, S/MIME signatures by the
right CA, subject names matching the grants, least-privilege topics), and ROS refuses to run a
node unsecured when security is enforced.

The PyPI Fast DDS is built without the security plugins (docs/SECURITY.md), so an authorised /
unauthorised exchange cannot be shown in this environment; the node start is checked to fail
closed instead."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

from conftest import REPO

SCRIPT = REPO / "security" / "keystore.sh"
pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl CLI not found")
DOMAIN = int(os.environ["ROS_DOMAIN_ID"])


def _run(*args, check=True, **kw):
    proc = subprocess.run([str(a) for a in args], capture_output=True, text=True, timeout=120,
                          **kw)
    if check and proc.returncode != 0:
        raise AssertionError(f"{args} failed ({proc.returncode}):\n{proc.stderr}")
    return proc


@pytest.fixture(scope="module")
def keystore(tmp_path_factory):
    ks = tmp_path_factory.mktemp("sec") / "keystore"
    _run("bash", SCRIPT, "profile", ks, DOMAIN)
    return ks


def _enclaves(ks):
    return sorted(p.parent for p in (ks / "enclaves").rglob("key.pem"))


def test_every_enclave_has_the_files_rcl_looks_up(keystore):
    names = sorted("/" + str(d.relative_to(keystore / "enclaves")) for d in _enclaves(keystore))
    listed = sorted(line.split()[0] for line in (REPO / "security" / "enclaves.txt")
                    .read_text().splitlines() if line.strip() and not line.startswith("#"))
    assert names == listed
    for d in _enclaves(keystore):
        for f in ("cert.pem", "key.pem", "identity_ca.cert.pem", "permissions_ca.cert.pem",
                  "governance.p7s", "permissions.p7s"):
            assert (d / f).is_file(), d / f
        assert stat.S_IMODE((d / "key.pem").stat().st_mode) == 0o600
    assert stat.S_IMODE((keystore / "private").stat().st_mode) & 0o077 == 0


def test_identity_certificates_chain_to_the_identity_ca_only(keystore):
    ca_id = keystore / "public" / "identity_ca.cert.pem"
    ca_perm = keystore / "public" / "permissions_ca.cert.pem"
    for d in _enclaves(keystore):
        assert _run("openssl", "verify", "-CAfile", ca_id, d / "cert.pem").stdout.strip() \
            .endswith("OK")
        assert _run("openssl", "verify", "-CAfile", ca_perm, d / "cert.pem",
                    check=False).returncode != 0
        subject = _run("openssl", "x509", "-in", d / "cert.pem", "-noout", "-subject",
                       "-nameopt", "RFC2253").stdout.strip()
        assert subject == f"subject=CN=/{d.relative_to(keystore / 'enclaves')}"
        text = _run("openssl", "x509", "-in", d / "cert.pem", "-noout", "-text").stdout
        assert "prime256v1" in text and "ecdsa-with-SHA256" in text and "CA:FALSE" in text


def _smime_verify(p7s, ca):
    return _run("openssl", "smime", "-verify", "-text", "-in", p7s, "-CAfile", ca, check=False)


def test_documents_are_signed_by_the_permissions_ca(keystore):
    ca_perm = keystore / "public" / "permissions_ca.cert.pem"
    ca_id = keystore / "public" / "identity_ca.cert.pem"
    gov = _smime_verify(keystore / "enclaves" / "governance.p7s", ca_perm)
    assert gov.returncode == 0, gov.stderr
    assert gov.stdout == (keystore / "enclaves" / "governance.xml").read_text()
    for d in _enclaves(keystore):
        perm = _smime_verify(d / "permissions.p7s", ca_perm)
        assert perm.returncode == 0, perm.stderr
        assert perm.stdout == (d / "permissions.xml").read_text()
        assert _smime_verify(d / "permissions.p7s", ca_id).returncode != 0


def test_tampered_permissions_fail_verification(keystore, tmp_path):
    d = keystore / "enclaves" / "ins_gnss" / "monitor"
    forged = tmp_path / "permissions.p7s"
    forged.write_text((d / "permissions.p7s").read_text().replace(
        "<topic>rt/diagnostics</topic>", "<topic>rt/ins/correction</topic>", 1))
    assert forged.read_text() != (d / "permissions.p7s").read_text()
    assert _smime_verify(forged, keystore / "public" / "permissions_ca.cert.pem").returncode != 0


def _grant(d):
    root = ET.fromstring((d / "permissions.xml").read_text())
    grant = root.find("permissions/grant")
    rule = grant.find("allow_rule")
    topics = {kind: {t.text for t in rule.findall(f"{kind}/topics/topic")}
              for kind in ("publish", "subscribe")}
    return grant, rule, topics


def test_grants_are_least_privilege_and_match_the_certificates(keystore):
    gov = ET.fromstring((keystore / "enclaves" / "governance.xml").read_text())
    rule = gov.find("domain_access_rules/domain_rule")
    assert rule.find("domains/id").text == str(DOMAIN)
    assert rule.find("allow_unauthenticated_participants").text == "false"
    assert rule.find("enable_join_access_control").text == "true"
    topic_rule = rule.find("topic_access_rules/topic_rule")
    for tag in ("enable_read_access_control", "enable_write_access_control"):
        assert topic_rule.find(tag).text == "true"
    for tag in ("metadata_protection_kind", "data_protection_kind"):
        assert topic_rule.find(tag).text == "ENCRYPT"

    nav_outputs = {"rt/ins/state", "rt/ins/correction", "rt/nav/odom", "rt/nav/fix",
                   "rt/nav/status", "rt/gnss/fix", "rt/gnss/heading", "rt/mag/heading"}
    publishers = {}
    for d in _enclaves(keystore):
        grant, allow, topics = _grant(d)
        name = "/" + str(d.relative_to(keystore / "enclaves"))
        assert grant.find("subject_name").text == f"CN={name}"
        assert allow.find("domains/id").text == str(DOMAIN)
        assert grant.find("default").text == "DENY"
        for t in nav_outputs & topics["publish"]:
            publishers.setdefault(t, []).append(name)
    # Exactly one writer per navigation output; the monitor may read but never write them.
    assert publishers["rt/ins/state"] == ["/ins_gnss/strapdown"]
    assert publishers["rt/ins/correction"] == ["/ins_gnss/ekf"]
    assert sorted(publishers["rt/gnss/fix"]) == ["/ins_gnss/gnss_driver",
                                                  "/ins_gnss/gnss_simulator"]
    _, _, monitor = _grant(keystore / "enclaves" / "ins_gnss" / "monitor")
    assert not monitor["publish"] & nav_outputs and "rt/ins/state" in monitor["subscribe"]


@pytest.mark.parametrize("args, message", [
    (["init", "{ks}", "300"], "domain id must be 0..232"),
    (["enclave", "{ks}", "bad name", "a", "b"], "is not a keystore"),
    (["bogus"], "init"),
])
def test_bad_arguments_exit_2_with_a_message(tmp_path, args, message):
    args = [a.format(ks=tmp_path / "ks") for a in args]
    proc = _run("bash", SCRIPT, *args, check=False)
    assert proc.returncode == 2 and message in proc.stderr


def test_topic_names_cannot_inject_xml(tmp_path):
    ks = tmp_path / "ks"
    _run("bash", SCRIPT, "init", ks, DOMAIN)
    for topic in ["a</topic><topic>*", "a b", "rt/*", "../x"]:
        proc = _run("bash", SCRIPT, "enclave", ks, "/x", topic, "-", check=False)
        assert proc.returncode == 2 and "not a ROS topic name" in proc.stderr
        shutil.rmtree(ks / "enclaves" / "x", ignore_errors=True)
    proc = _run("bash", SCRIPT, "enclave", ks, "/bad/../name", "a", "-", check=False)
    assert proc.returncode == 2 and "enclave name" in proc.stderr


NODE = ("import rclpy; from rclpy.node import Node; rclpy.init(); Node('strapdown');"
        " print('STARTED')")


def _start_node(env_extra, *ros_args):
    env = dict(os.environ, **env_extra)
    code = NODE.replace("rclpy.init()", f"rclpy.init(args={list(ros_args)!r})")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60, env=env)


def test_enforced_security_without_keystore_refuses_to_start(tmp_path):
    proc = _start_node({"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
                        "ROS_SECURITY_KEYSTORE": str(tmp_path / "none")})
    assert proc.returncode != 0 and "STARTED" not in proc.stdout
    assert "SECURITY ERROR" in proc.stderr


def test_enforced_security_never_falls_back_to_plain_dds(keystore):
    """With a valid enclave the node either runs secured or does not run. The PyPI Fast DDS has
    no security plugins, so here it must not run (the failure docs/SECURITY.md quotes)."""
    proc = _start_node({"ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce",
                        "ROS_SECURITY_KEYSTORE": str(keystore)},
                       "--ros-args", "--enclave", "/ins_gnss/strapdown")
    if "STARTED" in proc.stdout:
        pytest.skip("this Fast DDS has the security plugins: add the authorised/unauthorised "
                    "exchange test described in docs/SECURITY.md")
    assert proc.returncode != 0
    assert "Found security directory" in proc.stderr
    assert "doesn't have the security libraries" in proc.stderr
