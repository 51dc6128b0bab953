"""fibrefit.board and fibrefit.calibrate: the photo route's entry points as the command line's
(the calibration itself is tested end to end in tests/photo_route.rs)."""

import pytest

import fibrefit


def test_board_writes_the_png_and_its_geometry(tmp_path):
    written = fibrefit.board(tmp_path / "b", paper="letter", window_mm=50)
    assert sorted(p.rsplit("/", 1)[-1] for p in written) == ["board.pdf", "board.png", "board.toml"]
    text = (tmp_path / "b" / "board.toml").read_text()
    assert 'family = "tag36h11"' in text and 'paper = "letter"' in text


def test_a_bad_option_or_photo_is_refused_by_name_and_nothing_written(tmp_path):
    with pytest.raises(fibrefit.FibrefitError, match="--paper"):
        fibrefit.board(tmp_path / "x", paper="b5")
    assert not (tmp_path / "x").exists()
    fibrefit.board(tmp_path / "b")
    junk = tmp_path / "junk.jpg"
    junk.write_bytes(b"not a photo")
    with pytest.raises(fibrefit.FibrefitError, match="junk.jpg"):
        fibrefit.calibrate(tmp_path / "b" / "board.toml", [junk], tmp_path / "cal")
    assert not (tmp_path / "cal").exists()
    # a RAW file that is not one: the same message as the command line's
    raw = tmp_path / "IMG_0001.dng"
    raw.write_bytes(b"II*\0" + b"\0" * 60)
    with pytest.raises(fibrefit.FibrefitError, match="IMG_0001.dng: cannot read photo as camera RAW / DNG"):
        fibrefit.calibrate(tmp_path / "b" / "board.toml", [raw], tmp_path / "cal")
    assert not (tmp_path / "cal").exists()


def test_the_lights_file_and_grid_options_are_checked_like_the_command_lines(tmp_path):
    fibrefit.board(tmp_path / "b")
    board = tmp_path / "b" / "board.toml"
    photo = tmp_path / "p0.jpg"
    photo.write_bytes(b"not read: the options are refused first")
    with pytest.raises(fibrefit.FibrefitError, match="not both"):
        fibrefit.calibrate(board, [photo], tmp_path / "cal", texels=(64, 64), px_per_mm=2.0)
    with pytest.raises(fibrefit.FibrefitError, match="encoding"):
        fibrefit.calibrate(board, [photo], tmp_path / "cal", encoding="gamma")
    lights = tmp_path / "lights.toml"
    lights.write_text('[[photo]]\nfile = "other.jpg"\nflash = true\n')
    with pytest.raises(fibrefit.FibrefitError, match="names none of the photos"):
        fibrefit.calibrate(board, [photo], tmp_path / "cal", lights=lights)
    with pytest.raises(fibrefit.FibrefitError, match="px-per-mm"):
        fibrefit.calibrate(board, [photo], tmp_path / "cal", px_per_mm=1000.0)
    assert not (tmp_path / "cal").exists()
