"""The HTML pages: ``render`` turns a run folder's record into ``report.html``;
``sweep_page`` draws ``sweep.html``."""
