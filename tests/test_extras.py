"""How the messages say to install an optional extra (dynid._extras)."""

from __future__ import annotations

import pytest

import dynid._extras as extras


def test_a_clone_is_told_to_install_its_own_extra(monkeypatch, tmp_path):
    root = extras._source_folder()
    if root is None:
        pytest.skip("dynid is installed from a wheel here, not run from a clone")
    monkeypatch.chdir(root)
    assert extras.install_hint("mujoco") == 'pip install -e ".[mujoco]"'
    monkeypatch.chdir(tmp_path)
    assert extras.install_hint("fleet") == f'pip install -e "{root}[fleet]"'


def test_an_installed_copy_is_told_to_install_from_pypi(monkeypatch):
    monkeypatch.setattr(extras, "_source_folder", lambda: None)
    assert extras.install_hint("ros") == 'pip install "dynid[ros]"'
