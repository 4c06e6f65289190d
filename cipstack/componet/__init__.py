"""CompoNet: node addressing, explicit messages, cyclic I/O refresh, routing.

``explicit``: the appendix E frames of a CompoNet master's explicit message and the slave-side
handler over a message router; ``network``: a simulated network (word allocation by node address,
cyclic refresh, duplicate and lost slaves); ``gateway``: the Connection Manager route (port 2) that
carries an Unconnected_Send from EtherNet/IP to a node.
"""

from .explicit import ExplicitRequest, ExplicitResponse, serve_explicit
from .gateway import COMPONET_PORT, CompoNetGateway
from .network import CompoNetNetwork, NodeState

__all__ = ["COMPONET_PORT", "CompoNetGateway", "CompoNetNetwork", "ExplicitRequest", "ExplicitResponse",
           "NodeState", "serve_explicit"]
