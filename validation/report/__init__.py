"""The HTML pages. ``report.html`` of a run folder, one phase per module, imports pointing
one way (render -> build -> outcomes, plots -> read):

- ``read``: the run folder's record files (``load_run``), checked against ``validation.contract``;
- ``outcomes``: what a row, a (scene, engine) cell and a summary chip can be, and their colours;
- ``build``: the template's context (matrix, summary, offenders, scene sections, legend);
- ``plots``: matplotlib figures as inline SVG (also used by ``sweep_page``);
- ``render``: the entry points ``render_report`` and ``report_command``, the Jinja2
  environment (``templates/``) and the atomic write.

``sweep_page`` draws ``sweep.html``.
"""
