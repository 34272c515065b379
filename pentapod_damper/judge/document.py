"""
A report as a list of blocks, written as Markdown (with PNG files), self-contained HTML and CSV.

Blocks are headings, paragraphs, tables and figures. A table keeps its numbers as numbers and a
format per column, so the Markdown and HTML show them rounded while the CSV holds every number
of every table at full precision (one line per cell: table, row, column, value, unit). The
HTML embeds the figures (base64 PNG) and needs nothing else to be read.
"""
from __future__ import annotations

import base64
import csv
from dataclasses import dataclass, field
import html
import io
import math
from pathlib import Path
from typing import Sequence

#: A table cell: a number (shown with its column's format) or a text.
Cell = float | int | str | None


@dataclass
class Heading:
    """A heading of level 1-3."""

    text: str
    level: int = 2


@dataclass
class Paragraph:
    """A paragraph of plain text (Markdown emphasis and code marks are kept in Markdown)."""

    text: str


@dataclass
class Column:
    """A table column: its title, its unit (for the CSV) and the format of its numbers."""

    title: str
    unit: str = ''
    fmt: str = '.3g'


@dataclass
class Table:
    """A named table; ``rows[i][0]`` names the row in the CSV."""

    name: str
    columns: list[Column]
    rows: list[list[Cell]] = field(default_factory=list)

    def add(self, *cells: Cell) -> None:
        """Append one row."""
        if len(cells) != len(self.columns):
            raise ValueError(f'table {self.name}: {len(cells)} cells for '
                             f'{len(self.columns)} columns')
        self.rows.append(list(cells))


@dataclass
class Figure:
    """A PNG file with its caption."""

    path: Path
    caption: str


Block = Heading | Paragraph | Table | Figure


def show(cell: Cell, fmt: str) -> str:
    """A cell as text: numbers with ``fmt``, NaN and None as a dash."""
    if cell is None:
        return '-'
    if isinstance(cell, str):
        return cell
    if isinstance(cell, float) and not math.isfinite(cell):
        return '-' if math.isnan(cell) else ('inf' if cell > 0 else '-inf')
    return format(cell, fmt)


def _md_cell(text: str) -> str:
    return text.replace('|', '\\|').replace('\n', ' ')


def markdown(blocks: Sequence[Block], folder: Path) -> str:
    """Markdown text; figures link to their PNG files relative to ``folder``."""
    out = []
    for block in blocks:
        if isinstance(block, Heading):
            out.append(f'{"#" * block.level} {block.text}')
        elif isinstance(block, Paragraph):
            out.append(block.text)
        elif isinstance(block, Table):
            head = [f'{c.title} [{c.unit}]' if c.unit else c.title for c in block.columns]
            lines = ['| ' + ' | '.join(_md_cell(h) for h in head) + ' |',
                     '|' + '---|' * len(head)]
            for row in block.rows:
                lines.append('| ' + ' | '.join(_md_cell(show(v, c.fmt))
                                               for v, c in zip(row, block.columns)) + ' |')
            out.append('\n'.join(lines))
        else:
            rel = Path(block.path).resolve().relative_to(folder.resolve())
            out.append(f'![{block.caption}]({rel.as_posix()})\n\n*{block.caption}*')
    return '\n\n'.join(out) + '\n'


STYLE = ('body{font-family:sans-serif;max-width:70em;margin:2em auto;line-height:1.4}'
         'table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;'
         'padding:.2em .5em;text-align:right}td:first-child,th:first-child{text-align:left}'
         'img{max-width:100%}.pass{background:#dfd}.FAIL{background:#fcc}code{background:#eee}')


def _inline(text: str) -> str:
    """Escape text; `code` spans become <code>."""
    parts = html.escape(text).split('`')
    return ''.join(f'<code>{p}</code>' if i % 2 else p for i, p in enumerate(parts))


def html_page(blocks: Sequence[Block], title: str) -> str:
    """A self-contained HTML page (figures embedded)."""
    out = [f'<!DOCTYPE html><html><head><meta charset="utf-8"><title>{html.escape(title)}'
           f'</title><style>{STYLE}</style></head><body>']
    for block in blocks:
        if isinstance(block, Heading):
            out.append(f'<h{block.level}>{_inline(block.text)}</h{block.level}>')
        elif isinstance(block, Paragraph):
            out.append(f'<p>{_inline(block.text)}</p>')
        elif isinstance(block, Table):
            head = ''.join(f'<th>{_inline(c.title)}{f" [{html.escape(c.unit)}]" if c.unit else ""}'
                           '</th>' for c in block.columns)
            rows = []
            for row in block.rows:
                cells = []
                for v, c in zip(row, block.columns):
                    text = show(v, c.fmt)
                    cls = f' class="{text.split()[0]}"' if text.split()[:1] in (
                        ['pass'], ['FAIL']) else ''
                    cells.append(f'<td{cls}>{_inline(text)}</td>')
                rows.append('<tr>' + ''.join(cells) + '</tr>')
            out.append(f'<table><tr>{head}</tr>{"".join(rows)}</table>')
        else:
            data = base64.b64encode(Path(block.path).read_bytes()).decode('ascii')
            out.append(f'<figure><img src="data:image/png;base64,{data}" alt="'
                       f'{html.escape(block.caption)}"><figcaption>{_inline(block.caption)}'
                       '</figcaption></figure>')
    out.append('</body></html>')
    return '\n'.join(out)


def csv_text(blocks: Sequence[Block], prefix: Sequence[str] = ()) -> str:
    """Every cell of every table: ``prefix..., table, row, column, value, unit``."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator='\n')
    for block in blocks:
        if not isinstance(block, Table):
            continue
        for row in block.rows:
            name = show(row[0], block.columns[0].fmt)
            # a row of another unit than its columns names it: 'xx peak at [Hz]'
            own = name.rsplit(' [', 1)[1].rstrip(']') if name.endswith(']') else None
            for value, col in zip(row[1:], block.columns[1:]):
                text = ('' if value is None else repr(value) if isinstance(value, float)
                        else str(value))
                unit = own if own is not None and col.unit not in ('', '-') else col.unit
                writer.writerow([*prefix, block.name, name, col.title, text, unit])
    return buf.getvalue()


CSV_HEADER = ['table', 'row', 'column', 'value', 'unit']
