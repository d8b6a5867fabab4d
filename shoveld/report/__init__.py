"""The shift report: figures from the pass log (``figures``), written as HTML and CSV
(``write``)."""
