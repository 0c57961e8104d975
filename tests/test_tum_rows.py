"""TUM files read at once (np.loadtxt) equal the line-by-line reading, bit for bit, and
anything irregular falls back to it (its errors name the faulty line)."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.errors import InputError
from fuzzyslam.streams import tum


def test_written_trajectories_read_at_once_equal_line_by_line(tmp_path):
    rng = np.random.default_rng(5)
    n = 2000
    t = np.cumsum(rng.uniform(0.01, 0.3, n))
    poses = np.column_stack([rng.normal(0, 30, (n, 2)), rng.uniform(-np.pi, np.pi, n)])
    text = tum.format_tum(t, poses)
    fast = tum._regular_rows(text)
    slow, linenos = tum._parse_lines(tmp_path / "x.tum", text)
    assert fast is not None
    assert fast.tobytes() == slow.tobytes()
    assert linenos[0] == 2  # the header is a comment
    path = tmp_path / "t.tum"
    path.write_text(text)
    t2, p2 = tum.read_tum(path)
    assert np.array_equal(t2, slow[:, 0])
    assert np.allclose(p2[:, :2], poses[:, :2], atol=1e-6)


@pytest.mark.parametrize(
    "text",
    [
        "1 2 3 4 5 6 7 8\n\n  \n2 2 3 4 5 6 7 8",
        "\t1\t2 3 4 5 6 7 8\r\n",
        "+1 -2 3e0 4E-1 .5 6. 7 8\n",
        "  # comment\n1 2 3 4 5 6 7 8\n",
        "1 2 3 4 5 6 7 8\x0b2 2 3 4 5 6 7 8\n",  # a line break of str.splitlines
    ],
)
def test_regular_texts_read_at_once(text, tmp_path):
    fast = tum._regular_rows(text)
    assert fast is not None
    assert fast.tobytes() == tum._parse_lines(tmp_path / "x", text)[0].tobytes()


@pytest.mark.parametrize(
    "text",
    [
        "",
        "# only a header\n",
        "1,2,3,4,5,6,7,8\n",  # commas: line by line (they are read as blanks there)
        "1_0 2 3 4 5 6 7 8\n",  # float() reads it, loadtxt does not
        "1 2 3 4 5 6 7 8 # c\n",
        "1 2 3 4 5 6 7\n",
        "1 2 3 4 5 6 7 8\n1 2 3 4 5 6 7 8 9\n",
        "1 2 3 4 5 6 7 nan\n",
    ],
)
def test_irregular_texts_fall_back_to_line_by_line(text):
    assert tum._regular_rows(text) is None


def test_errors_still_name_the_line(tmp_path):
    path = tmp_path / "bad.tum"
    path.write_text("# h\n1 0 0 0 0 0 0 1\n3 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n")
    with pytest.raises(InputError, match=r"line 4: timestamp 2\.000000000 goes back before"):
        tum.read_tum(path)
    path.write_text("# h\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 inf 1\n")
    with pytest.raises(InputError, match="line 3: NaN or infinite value"):
        tum.read_tum(path)
