"""Sizes as text and the disk check of an output: every output estimated larger than the limit
or the free space is refused with one line naming both numbers; every other one passes."""

import re
import shutil

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nidar_mi.errors import NidarError
from nidar_mi.io.sizes import check_disk, format_size, free_space, parse_size

_BYTES = st.integers(min_value=1, max_value=1 << 60)


@given(n=_BYTES)
def test_a_formatted_size_reads_back_within_its_rounding(n):
    text = format_size(n).replace(" ", "").removesuffix("iB").removesuffix("B")
    assert abs(parse_size(text) - n) <= max(0.051 * n, 1)


@settings(deadline=None, max_examples=200)
@given(need=_BYTES, limit=st.one_of(st.none(), _BYTES), free=_BYTES)
def test_check_disk_refuses_exactly_what_does_not_fit(tmp_path_factory, need, limit, free):
    out = tmp_path_factory.getbasetemp() / "out"
    usage = shutil.disk_usage(tmp_path_factory.getbasetemp())
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(shutil, "disk_usage", lambda p: usage._replace(free=free))
        fits = need <= free and (limit is None or need <= limit)
        if fits:
            check_disk(need, out, "what")
            check_disk(need, out, "what", limit)
            return
        with pytest.raises(NidarError) as e:
            check_disk(need, out, "3 frames x 1 MiB", limit)
    message = str(e.value)
    assert "\n" not in message and f"needs about {format_size(need)} (3 frames x 1 MiB)" in message
    if limit is not None and need > limit:
        assert f"the limit of {format_size(limit)} (`max_disk`)" in message
    else:
        assert re.search(rf"the {re.escape(format_size(free))} free on /", message)


def test_free_space_of_a_folder_not_made_yet(tmp_path):
    assert free_space(tmp_path / "a" / "b") == shutil.disk_usage(tmp_path).free > 0
