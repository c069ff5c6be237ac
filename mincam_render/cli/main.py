"""The ``mincam-render`` command line: one entry point, its subcommands registered here.

Each command group lives in its own module (``transport``, ``preview``, ``train``,
``render``, ``studies``, ``bench``, ``report``); shared option types and callbacks
in ``options``, the one-line error reporting in ``errors``. Commands import
torch and Mitsuba only in their bodies, so ``--help`` starts at once.
"""

from __future__ import annotations

import logging

import click

from mincam_render.cli import bench, preview, render, report, studies, train, transport
from mincam_render.cli.errors import Stopped, stop_on_signals, stopped_error


class _StoppableGroup(click.Group):
    """The entry point: a stop signal ends any command in one line (:func:`stop_on_signals`)."""

    def invoke(self, ctx: click.Context) -> object:
        """Run the command; a :class:`Stopped` becomes its one line and exit code."""
        try:
            return super().invoke(ctx)
        except Stopped as stop:
            raise stopped_error(stop.signum) from None


@click.group(cls=_StoppableGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", is_flag=True, help="Log debug messages.")
@click.pass_context
def main(ctx: click.Context, verbose: bool) -> None:
    """Render, train and export minimalist cameras of freeform pixels."""
    stop_on_signals(ctx)
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format="%(levelname)s %(name)s: %(message)s",
    )


for _command in (
    transport.transport_cmd,
    preview.preview_cmd,
    train.train_cmd,
    train.sweep_cmd,
    train.prune_cmd,
    train.export_masks_cmd,
    render.render_cmd,
    render.export_exr_cmd,
    render.repair_cmd,
    studies.pipeline_cmd,
    studies.study_cmd,
    bench.bench_group,
    report.report_group,
):
    main.add_command(_command)


if __name__ == "__main__":
    main()
