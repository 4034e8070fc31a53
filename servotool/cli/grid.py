"""Tables as the commands build them (`render.table`), drawn here when rich has nothing to add.

A Grid holds columns and rows as a rich Table does (same attribute names, so `render.fit` and the commands treat
both alike) and becomes one (`rich()`, or rich's `__rich__` protocol) wherever rich draws it. Where no style can
show (a pipe, a file) a table of plain one-line ASCII cells that fits the width as it is comes out exactly as rich
would draw it, without importing rich: a quarter of a one-shot command's start-up.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.table import Table

# rich's box.HEAVY_HEAD, its default: top, header row, header rule, body row, bottom (left, fill, divider, right).
TOP, HEAD, HEAD_RULE, ROW, BOTTOM = "┏━┳┓", "┃ ┃┃", "┡━╇┩", "│ ││", "└─┴┘"


class Column:
    """One column: the settings a rich Column takes, and its cells. (A plain class: a dataclass costs ~0.5 ms to
    create at start-up.)"""

    def __init__(
        self,
        header: str,
        justify: str = "left",
        overflow: str = "fold",
        no_wrap: bool = False,
        width: int | None = None,
        max_width: int | None = None,
        cells: list[Any] | None = None,
    ) -> None:
        self.header, self.justify, self.overflow, self.no_wrap = header, justify, overflow, no_wrap
        self.width, self.max_width = width, max_width
        self._cells: list[Any] = cells if cells is not None else []


class Grid:
    """A table of cells, drawn by rich or, when that changes nothing, by `plain`."""

    def __init__(self, title: str | None = None, drop: tuple[str, ...] = ()) -> None:
        self.title = title
        self.show_lines = False
        self.header_style = "bold"
        self.title_justify = "left"
        self.drop = drop
        self.columns: list[Column] = []

    @property
    def row_count(self) -> int:
        return len(self.columns[0]._cells) if self.columns else 0

    def add_column(
        self,
        header: str,
        *,
        justify: str = "left",
        overflow: str = "fold",
        no_wrap: bool = False,
        width: int | None = None,
        max_width: int | None = None,
    ) -> None:
        self.columns.append(Column(header, justify, overflow, no_wrap, width, max_width, [""] * self.row_count))

    def add_row(self, *cells: Any) -> None:
        if len(cells) > len(self.columns):
            raise ValueError(f"{len(cells)} cells for {len(self.columns)} columns")
        for i, column in enumerate(self.columns):
            cell = cells[i] if i < len(cells) else None
            column._cells.append("" if cell is None else cell)

    def rich(self) -> Table:
        from rich.table import Table

        t = Table(
            title=self.title,
            show_lines=self.show_lines,
            header_style=self.header_style,
            title_justify=self.title_justify,
        )  # type: ignore[arg-type]
        for c in self.columns:
            t.add_column(
                c.header,
                justify=c.justify,
                overflow=c.overflow,
                no_wrap=c.no_wrap,  # type: ignore[arg-type]
                width=c.width,
                max_width=c.max_width,
            )
        for row in zip(*(c._cells for c in self.columns), strict=True):
            t.add_row(*row)
        return t

    def __rich__(self) -> Table:
        return self.rich()

    def plain(self, width: int) -> str | None:
        """The table as rich draws it without styles in `width` columns, or None when only rich can draw it
        (cells that are not plain one-line ASCII text, a table to fit, a setting drawn here as rich does not)."""
        if not self.columns or not self.row_count or self.show_lines or self.title_justify != "left":
            return None
        texts = [[c.header, *c._cells] for c in self.columns]
        if not all(_plain(x) for cells in texts for x in cells):
            return None
        widths = [max(map(len, cells)) for cells in texts]
        for c, w in zip(self.columns, widths, strict=True):
            if (
                c.width is not None
                or (c.max_width is not None and c.max_width < w)
                or c.justify not in ("left", "right")
            ):
                return None
        span = sum(widths) + 3 * len(widths) + 1
        if span > width or (self.title and (not _plain(self.title) or len(self.title) > span)):
            return None

        def rule(box: str) -> str:
            return box[0] + box[2].join(box[1] * (w + 2) for w in widths) + box[3]

        def row(box: str, cells: list[str]) -> str:
            padded = (
                cell.rjust(w) if c.justify == "right" else cell.ljust(w)
                for cell, w, c in zip(cells, widths, self.columns, strict=True)
            )
            return box[0] + box[2].join(f" {p} " for p in padded) + box[3]

        lines = [self.title.ljust(span)] if self.title else []
        lines += [rule(TOP), row(HEAD, [c.header for c in self.columns]), rule(HEAD_RULE)]
        lines += [row(ROW, list(cells)) for cells in zip(*(c._cells for c in self.columns), strict=True)]
        lines.append(rule(BOTTOM))
        return "\n".join(lines) + "\n"


def _plain(text: object) -> bool:
    """Text rich prints as it is: one line of printable ASCII (one column a character) without markup, nor spaces
    at either end (rich trims them in some alignments)."""
    return type(text) is str and text.isascii() and text.isprintable() and "[" not in text and text == text.strip()
