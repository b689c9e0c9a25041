"""rlcore.render.realtime_gif: a GIF that plays in real time, and the numbers its caption states."""

import io

import pytest
from PIL import Image

from rlcore.render import Clip, realtime_gif


def _frames_and_durations(data: bytes) -> tuple[int, list[int]]:
    gif = Image.open(io.BytesIO(data))
    durations = []
    for i in range(gif.n_frames):
        gif.seek(i)
        durations.append(gif.info["duration"])
    return gif.n_frames, durations


def test_cartpole_clip_keeps_every_second_step_and_plays_in_real_time():
    clip = realtime_gif("CartPole-v1", policy=lambda obs: int(obs[2] > 0), seconds=0.4, fps=25)
    assert (clip.frame_skip, clip.frames) == (2, 10)              # tau = 0.02 s: a frame every 0.04 s
    assert clip.step_seconds == pytest.approx(0.02)
    assert clip.fps == pytest.approx(25) and clip.seconds == pytest.approx(0.4)
    n, durations = _frames_and_durations(clip.gif)
    # 40 ms a frame, 0.4 s in all: real time (identical consecutive frames are merged into one longer frame)
    assert n <= 10 and sum(durations) == 400 and min(durations) == 40
    text = clip.caption()
    assert text.startswith("0.4 s of simulation in real time: 10 frames at 25 per second, one every 2 steps of 0.02 s")
    assert f"({len(clip.gif) / 1e6:.2f} MB)" in text


def test_a_step_longer_than_a_frame_keeps_every_step_and_rounds_to_whole_frames():
    clip = realtime_gif("Pendulum-v1", seconds=0.33, fps=25, seed=1)  # dt = 0.05 s: 20 frames per second at most
    assert clip.frame_skip == 1 and clip.fps == pytest.approx(20)
    assert clip.frames == 7 and clip.seconds == pytest.approx(0.35)  # 0.33 s is closest to 7 frames of 0.05 s
    assert "one every step of 0.05 s" in clip.caption()
    assert sum(_frames_and_durations(clip.gif)[1]) == 350


def test_bad_lengths_are_refused():
    for seconds, fps in ((0, 25), (1, 0), (-1, 25)):
        with pytest.raises(ValueError):
            realtime_gif("CartPole-v1", seconds=seconds, fps=fps)


def test_clip_numbers_follow_from_frames_skip_and_step():
    clip = Clip(b"GIF89a", "Hopper-v5", frames=150, frame_skip=5, step_seconds=0.008)
    assert clip.seconds == pytest.approx(6.0) and clip.fps == pytest.approx(25)


def test_frames_last_whole_hundredths_of_a_second_where_a_nearby_step_count_allows():
    from rlcore.render import realtime_frame_skip

    assert realtime_frame_skip(0.008) == 5       # Hopper: 40 ms, 25 per second
    assert realtime_frame_skip(0.05) == 1        # HalfCheetah, Ant, Pendulum: 50 ms
    assert realtime_frame_skip(0.015) == 2       # Humanoid: 30 ms, not 3 steps of 45 ms (GIF would play 40 or 50)
    assert realtime_frame_skip(0.02) == 2        # CartPole
    assert realtime_frame_skip(0.033) == 1       # no whole-hundredths count nearby: the nearest count
    assert realtime_frame_skip(0.3) == 1         # a step longer than a frame: every step
