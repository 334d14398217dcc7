"""``robofabric console``: the paper's student client in a browser, served by one process to a whole class.

:mod:`.server` (the app, one zenoh session per logged-in student), :mod:`.login` (her own credentials, the
grace after her page goes), :mod:`.page` (the window: robots, live view, events), :mod:`.arm_panel` and
:mod:`.base_panel` (its two panels),
:mod:`.state` and :mod:`.topview` (what the page draws, pure), :mod:`.drive` (keys to a twist, pure).
"""
