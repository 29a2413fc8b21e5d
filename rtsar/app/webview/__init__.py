"""``rtsar view --http``: the live waterfall served to browsers by the viewing process itself.

``frames`` keeps what the page shows (rows of pooled image lines and heights, the run's status) in
bounded memory; ``server`` serves the page from ``static/`` and pushes updates over WebSocket;
``access`` decides who may read it (the WebSocket's origin, the optional token).
"""
