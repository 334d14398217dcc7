"""``robofabric console``: the paper's student client in a browser, served by one process to a whole class.

:mod:`.server` (the app, one zenoh session per logged-in student), :mod:`.login` (her own credentials, the
grace after her page goes), :mod:`.page` (the window: robots, live view, events), :mod:`.panels` (the one list of
its robot panels: :mod:`.arm_panel`, :mod:`.base_panel`) and :mod:`.panel` (what a page calls on a panel),
:mod:`.state` and :mod:`.topview` (what the page draws, pure), :mod:`.drive` (keys to a twist, pure).
"""
