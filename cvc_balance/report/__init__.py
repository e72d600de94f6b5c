"""
The field-balancing report a service engineer reads: one HTML page and its PNG figures.

Renders the correction summary (:mod:`cvc_balance.cli.field`'s JSON, the docs' "Field
balancing"); matplotlib draws the figures. Public API: :func:`write_report`.
"""

from pathlib import Path

from cvc_balance.report.figures import grade_figure, plane_figure, readings_figure
from cvc_balance.report.page import page


def write_report(summary, directory, generated=None):
    """
    Write ``directory``/report.html and its PNG figures; return the files written.

    The page first, then per correction plane a polar plot, the grade chart (with a
    grade) and the readings chart (with influence coefficients).
    """
    directory = Path(directory)
    figures = []
    for k, plane in enumerate(summary['planes']):
        name = f'plane_{plane["name"]}.png'
        plane_figure(summary, k, directory / name)
        figures.append((name, f'plane {plane["name"]}: before, after and the weights at '
                        'their sites'))
    if summary['grade'] is not None:
        grade_figure(summary, directory / 'grade.png')
        figures.append(('grade.png', 'equivalent grade before and after'))
    if summary['coefficients'] is not None:
        readings_figure(summary, directory / 'readings.png')
        figures.append(('readings.png', '1x readings before and predicted after'))
    report = directory / 'report.html'
    report.write_text(page(summary, figures, generated), encoding='utf-8')
    return [report] + [directory / name for name, _ in figures]


__all__ = ['write_report']
