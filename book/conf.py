"""Sphinx configuration of the study book (``make book``; ``tools/build_book.py`` passes this folder
with ``-c`` and a source tree it assembles from results/<profile>/). Notebooks are rendered from
their stored outputs, never executed."""
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))

PROFILE = os.environ.get("BOOK_PROFILE", "paper")
project = f"Deep Recursive Filters: the study book ({PROFILE})"
author = "the study book's authors"
copyright = "the study book's authors"

extensions = ["myst_nb"]
myst_enable_extensions = ["colon_fence", "dollarmath", "amsmath"]
myst_heading_anchors = 3
myst_heading_slug_func = "booklib.slugify"  # the anchors build_book.py links to (an import path: cacheable)
nb_execution_mode = "off"
nb_output_stderr = "show"
nb_merge_streams = True

exclude_patterns = ["_build", "**.ipynb_checkpoints"]
nitpicky = True
html_theme = "sphinx_book_theme"
html_title = "Deep Recursive Filters: study book"
html_theme_options = {
    "show_toc_level": 2,
    "use_download_button": True,
    "home_page_in_toc": True,
}
html_last_updated_fmt = None
html_show_sourcelink = False
