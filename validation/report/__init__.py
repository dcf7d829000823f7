"""The HTML pages. ``report.html`` of a run folder, one phase per module, imports pointing
one way (render -> build -> outcomes, plots -> read):

- ``read``: the run folder's record files (``load_run``), checked against ``validation.contract``;
- ``outcomes``: what a row, a (scene, engine) cell and a summary chip can be, and their colours;
- ``build``: the template's context (matrix, summary, offenders, scene sections, legend);
- ``closed_form``: the quantity under test against its closed form (trace.csv's rows, the
  charts of a scene card);
- ``plots``: the conserved quantities and e against impact speed as charts;
- ``svgchart``: report.html's and sweep.html's charts written directly as inline SVG (no
  matplotlib; history.html's trend plots stay matplotlib figures), and
  ``palette``: one colour and dash per engine spec on every page;
- ``templating``: the Jinja2 environment and the frame every page shares (``templates/
  base.html.j2``, ``templates/style.css``);
- ``render``: the entry points ``render_report`` and ``report_command`` and the atomic write.

``sweep_page`` draws ``sweep.html``.
"""
