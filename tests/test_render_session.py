"""The render session: options checked before anything loads, the cache key, the scene loaded in
the variant the entry point chose (and refused without one), the sequence's options."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from nidar_mi import render_folder as rf
from nidar_mi.errors import NidarError
from nidar_mi.render_session import RenderOptions, RenderSession, check_options

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = os.path.join(REPO, "scenes", "target.xml")


def test_key_is_the_render_request():
    options = RenderOptions(TARGET, seed=3, spp=2, params={"cols": "64"}, progress=False)
    assert options.key() == rf.RenderRequest.of(
        TARGET, seed=3, spp=2, params={"cols": "64"}, nidar_branch="R"
    )
    # NIDAR's options count only with --intensity nidar; the branch defaults to R
    nidar = RenderOptions(TARGET, intensity="nidar").key()
    assert nidar.nidar_branch == "R" and options.key().nidar_branch is None
    # how a render runs is not part of its key
    assert RenderOptions(TARGET, max_memory=1, deskew=True).key() == RenderOptions(TARGET).key()


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(weights="w"), "`weights` is used only with `intensity` nidar"),
        (dict(nidar_branch="R"), "`nidar_branch` is used only with `intensity` nidar"),
        (dict(spp=0), "`spp` must be >= 1"),
        (dict(intensity="nidar", cameras=False), "needs the camera renders"),
        (dict(formats=("npz", "xyz")), "`formats`: unknown 'xyz'"),
        (dict(bin_intensity="half"), "`bin_intensity` must be one of"),
    ],
)
def test_bad_options_are_refused_before_loading(options, message):
    with pytest.raises(NidarError, match=message):
        check_options(RenderOptions(TARGET, **options))


def test_a_missing_scene_is_named():
    with pytest.raises(NidarError, match="no such scene file"):
        check_options(RenderOptions(os.path.join(REPO, "scenes", "nope.xml")))


def test_session_loads_in_the_active_variant(variant):
    session = RenderSession.open(RenderOptions(TARGET, params={"cols": "64"}, cameras=False))
    assert session.variant == variant
    assert [s.id() for s in session.lidars] == ["lidar"] and session.cameras == []
    assert session.nir_wavelengths == [905.0]
    assert set(session.versions) == {"nidar_mi", "mitsuba", "drjit", "numpy", "python"}
    session.check_memory()  # a small scan fits


def test_session_refuses_a_scan_over_the_memory_limit(variant):
    session = RenderSession.open(RenderOptions(TARGET, max_memory=1024))
    with pytest.raises(NidarError):
        session.check_memory()


def test_library_code_does_not_choose_the_variant():
    """Without a variant set by the entry point, loading a scene is refused (one line)."""
    code = (
        "from nidar_mi.errors import NidarError\n"
        "from nidar_mi.scene import load_scene\n"
        "try:\n"
        f"    load_scene({TARGET!r})\n"
        "except NidarError as e:\n"
        "    print(e)\n"
        "import mitsuba as mi\n"
        "print(mi.variant())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    ).stdout.splitlines()
    assert out[0].startswith("no spectral Mitsuba variant is active") and out[1] == "None"


def test_another_variant_than_the_active_one_is_refused(variant):
    from nidar_mi.scene import load_scene

    with pytest.raises(NidarError, match="is not the active one"):
        load_scene(TARGET, variant="cuda_ad_spectral")


@pytest.mark.parametrize(
    "options, message",
    [
        (dict(rate=0.0), "`rate` must be > 0 Hz"),
        (dict(frames=0), "`frames` must be >= 1"),
        (dict(sequence_formats=("mcap",)), "`sequence_formats`: unknown 'mcap'"),
        (dict(spp=0), "`spp` must be >= 1"),
        (dict(trajectory="nope.txt"), "nope.txt: no such trajectory file"),
    ],
)
def test_sequence_options_are_checked_before_loading(tmp_path, options, message):
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions, check_sequence

    traj = tmp_path / "poses.txt"
    traj.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    frame = RenderOptions(TARGET, **{k: v for k, v in options.items() if k == "spp"})
    options = {"trajectory": str(traj)} | {k: v for k, v in options.items() if k != "spp"}
    with pytest.raises(NidarError, match=message):
        check_sequence(SequenceOptions(frame, **options))


def test_sequence_frames_are_rendered_with_physics_intensity(tmp_path):
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions, check_sequence

    traj = tmp_path / "poses.txt"
    traj.write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    frame = RenderOptions(TARGET, intensity="nidar")
    with pytest.raises(NidarError, match="`intensity`: a sequence renders the physics intensity"):
        check_sequence(SequenceOptions(frame, str(traj)))
