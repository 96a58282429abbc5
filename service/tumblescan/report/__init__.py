"""The report shell every kind's HTML report is built in (plotly inlined, works offline)."""

from .html import CSS, figure_html, image_html, page, sigmas_text, table_html, value_text

__all__ = ["CSS", "figure_html", "image_html", "page", "sigmas_text", "table_html", "value_text"]
