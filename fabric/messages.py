"""The fabric's messages under their first name: a thin re-export of :mod:`fabric.interfaces`.

Kept for users' scripts and notebooks written as ``from fabric.messages import Pose``; the types live
in :mod:`fabric.interfaces` (one module per kind), and robofabric's own code imports them from there.
"""

from fabric.interfaces import *  # noqa: F401,F403
from fabric.interfaces import __all__  # noqa: F401
