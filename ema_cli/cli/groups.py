"""Command groups with a default command: `ema identify torque ...` and `ema identify [CONFIG]
--flags ...` both work.

A :class:`DefaultGroup` runs its subcommand when the first word after the group's name is one;
anything else (nothing, an option, a positional CONFIG path) goes to the group's *default*
command, a hidden command holding the spelling of earlier versions. ``ema identify --help``
lists the subcommands with their whole summaries, then the default command's options.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import typer
from typer import _click  # typer >= 0.29 vendors click; its classes are these
from typer.core import TyperGroup

DEFAULT_NAME = "default"
"""The hidden name the default command is registered under."""


class _DefaultContext(_click.Context):
    """The default command's context: its command path is the group's (usage lines and error
    hints read `ema identify [OPTIONS] [CONFIG]`, not the hidden name)."""

    @property
    def command_path(self) -> str:
        return self.parent.command_path if self.parent is not None else super().command_path


def summary(cmd: _click.Command) -> str:
    """A command's whole summary: its ``short_help`` or the first paragraph of its help, on one
    line (click would cut it at ~45 characters)."""
    text = cmd.short_help or (cmd.help or "").split("\n\n")[0]
    return " ".join(text.split())


class DefaultGroup(TyperGroup):
    """A group that resolves anything that is not one of its subcommands to its default command
    (registered as :data:`DEFAULT_NAME`, hidden)."""

    def __init__(self, **attrs: Any) -> None:
        super().__init__(**attrs)
        default = self.commands.get(DEFAULT_NAME)
        if default is not None:
            default.context_class = _DefaultContext

    def parse_args(self, ctx: _click.Context, args: list[str]) -> list[str]:
        first = args[0] if args else None
        if first not in self.commands and first not in ctx.help_option_names:
            args = [DEFAULT_NAME, *args]  # no command named: the default one, with every word
        return super().parse_args(ctx, args)

    def format_usage(self, ctx: _click.Context, formatter: _click.HelpFormatter) -> None:
        formatter.write_usage(ctx.command_path, "COMMAND [ARGS]... | [CONFIG] [OPTIONS]")

    def format_commands(self, ctx: _click.Context, formatter: _click.HelpFormatter) -> None:
        rows = [(name, summary(cmd)) for name, cmd in self.commands.items() if not cmd.hidden]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def format_options(self, ctx: _click.Context, formatter: _click.HelpFormatter) -> None:
        self.format_commands(ctx, formatter)
        default = self.commands.get(DEFAULT_NAME)
        if default is None:
            return
        sub = default.context_class(default, info_name=DEFAULT_NAME, parent=ctx)
        with formatter.section(f"Without a command: {ctx.command_path} [CONFIG] [OPTIONS]"):
            formatter.write_text(summary(default))
        default.format_options(sub, formatter)


def command_group(name: str, default: Callable[..., Any],
                  subcommands: Sequence[tuple[str, Callable[..., Any]]], help: str) -> typer.Typer:
    """A typer group ``name`` running ``default`` when no subcommand is named and each
    ``(name, function)`` of ``subcommands`` as ``<group> <name>``, in that order. Registering a
    subcommand is one more pair."""
    group = typer.Typer(name=name, cls=DefaultGroup, help=help, rich_markup_mode=None,
                        add_completion=False, no_args_is_help=False,
                        pretty_exceptions_enable=False)
    group.command(DEFAULT_NAME, hidden=True)(default)
    for sub_name, fn in subcommands:
        group.command(sub_name)(fn)
    return group

