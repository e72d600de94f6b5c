"""
Sphinx configuration of cvc_balance's documentation (MyST Markdown).

Built by ``./dev.sh docs`` (warnings are errors). The reference pages under ``reference/``
are written at build time from the code they describe (the argparse parsers, the node's
declarations) by the local extension ``_ext/cvc_reference.py``; they are never edited by
hand and never committed.
"""

from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).parent / '_ext'))

project = 'cvc_balance'
author = 'cvc_balance developers'
copyright = '2026, cvc_balance developers (Apache-2.0)'
extensions = ['myst_parser', 'cvc_reference', 'cvc_formats']
source_suffix = {'.md': 'markdown'}
root_doc = 'index'
exclude_patterns = ['_build', 'README.md']
myst_heading_anchors = 3
myst_enable_extensions = ['deflist']
html_theme = 'alabaster'
html_theme_options = {'page_width': '1100px', 'sidebar_width': '240px'}
html_title = 'cvc_balance'
# Pictures live beside the pages that show them (docs/*.png); nothing is fetched at build.
html_static_path = ['_static']
html_css_files = ['cvc.css']     # console output wraps instead of scrolling
smartquotes = False   # options keep their two hyphens (--target-probability)
