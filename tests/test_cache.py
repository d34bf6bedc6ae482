"""The compiled-library cache is bounded (least recently used first) and can be listed and
cleared (``cmm-dae cache``)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import casadi as ca
import pytest

from cmm_dae.equations import codegen, libcache


def tiny(k: int) -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function(f"f{k}", [x], [x * k + 1.0])


def build(k: int):
    fn = tiny(k)
    return codegen.build_library(codegen.function_key([fn]), None, [fn])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    if codegen.c_compiler() is None:  # pragma: no cover - CI and this machine have gcc
        pytest.fail("these tests need a C compiler (gcc or cc)")
    monkeypatch.setenv("CMM_DAE_CACHE", str(tmp_path))
    return tmp_path


def test_the_cache_is_trimmed_least_recently_used_first(cache, monkeypatch):
    libs = [build(k) for k in (1, 2, 3)]
    assert [e.path for e in libcache.entries()] == libs  # oldest first
    size = max(e.size for e in libcache.entries())
    # a cap that holds two: the least recently used (the first, unless used since) goes
    old = time.time() - 100.0
    os.utime(libs[1], (old, old))  # used long ago
    monkeypatch.setenv("CMM_DAE_CACHE_MB", str(2.5 * size / 2**20))
    lib4 = build(4)
    left = {e.path for e in libcache.entries()}
    assert lib4 in left and libs[1] not in left and len(left) == 2
    assert not libs[1].with_name(libs[1].name + ".ok").exists()
    # a library removed is built again when asked for
    again = build(2)
    assert again == libs[1] and again.exists()


def test_the_cap_never_removes_the_library_just_built(cache, monkeypatch):
    monkeypatch.setenv("CMM_DAE_CACHE_MB", "1e-9")
    lib = build(5)
    assert [e.path for e in libcache.entries()] == [lib]


def test_cli_lists_and_clears(cache):
    build(6)
    build(7)
    env = dict(os.environ)
    run = [sys.executable, "-m", "cmm_dae.cli", "cache"]
    r = subprocess.run([*run, "--list"], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0 and "2 libraries" in r.stdout
    assert r.stdout.count("cmm_") == 2
    r = subprocess.run([*run, "--clear"], capture_output=True, text=True, env=env, timeout=60)
    assert r.returncode == 0 and "removed 2 libraries" in r.stdout
    assert libcache.entries() == [] and not list(cache.glob("cmm_*"))
