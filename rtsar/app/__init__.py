"""The applications: the ``rtsar`` command (``cli``), the live runner and its status line
(``live``), subscribers (``subscribe``, ``view``), quicklooks, ``bench``, ``tradeoff``,
``table1`` and the reports behind the tools/ scripts (``reports``).

The only floor of rtsar that parses arguments, prints or draws.
"""
