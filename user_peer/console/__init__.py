"""``robofabric console``: the paper's student client in a browser, served by one process to a whole class.

:mod:`.server` (the app, one zenoh session per logged-in page), :mod:`.login` (her own credentials, the
grace after her page goes), :mod:`.page` (the window: robots, arm, base, live view, events),
:mod:`.state` and :mod:`.topview` (what the page draws, pure), :mod:`.drive` (keys to a twist, pure).
"""
