"""One writer per output directory: a second render or training fails at once; kills release."""

import subprocess
import sys
import time

import pytest

from mincam_render.data.render_job import RenderRequest, render_dataset
from mincam_render.data.writer_lock import LOCK_NAME, WriterBusy, exclusive_writer
from mincam_render.learn import train as tr

HOLD = (
    "import sys, time\n"
    "from mincam_render.data.writer_lock import exclusive_writer\n"
    "with exclusive_writer(sys.argv[1], 'render'):\n"
    "    print('locked', flush=True)\n"
    "    time.sleep(60)\n"
)


def test_a_second_writer_fails_at_once_and_a_killed_holder_releases(tmp_path):
    out = tmp_path / "ds"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == b"locked"
        t0 = time.monotonic()
        with pytest.raises(WriterBusy, match="being written by another process"):
            with exclusive_writer(out, "render"):
                pass
        assert time.monotonic() - t0 < 1.0  # never waits
        request = RenderRequest(family="patches", num_frames=4, spp=1, mask_res=8)
        with pytest.raises(WriterBusy):
            render_dataset(request, out, workers=0)
    finally:
        holder.kill()
        holder.wait()
    with exclusive_writer(out, "render"):  # the kernel dropped the killed holder's lock
        assert (out / LOCK_NAME).is_file()


def test_training_into_a_locked_directory_is_refused(tmp_path):
    from support import linear_task

    train, val, test = linear_task(60).split((0.6, 0.2, 0.2))
    cfg = tr.TrainConfig(max_steps=5, batch_size=8, eval_every=5)
    with exclusive_writer(tmp_path / "run", "training"):
        with pytest.raises(WriterBusy, match="wait for that training"):
            tr.train_run(train, val, test, tmp_path / "run", pixels=1, config=cfg)


def test_a_failed_start_leaves_no_directory(tmp_path):
    out = tmp_path / "new"
    with pytest.raises(RuntimeError):
        with exclusive_writer(out, "render"):
            raise RuntimeError("planning failed")
    assert not out.exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match="not a directory"):
        with exclusive_writer(tmp_path / "file", "render"):
            pass
