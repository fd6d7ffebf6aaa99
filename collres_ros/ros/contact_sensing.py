"""What touches what, for controllers: per-body ``in_contact`` topics and ``get_contacts``.

* ``bodies/<name>/in_contact`` (std_msgs/Bool; reliable, transient local, keep last 1: a
  subscriber that joins later gets the current state), for every body of the scene while
  ``contact_state`` is true: ``false`` once at start, then on every change of the body's
  debounced state (``core/contact_state.py``: on when the normal impulses on it in one step
  sum to more than ``contact_on_impulse``, off after ``contact_off_steps`` steps without).
* ``get_contacts`` (collres_ros/srv/GetContacts): the last step's contacts that involve the
  requested bodies (all of them for an empty request), as published on ``contacts``,
  answered from the stored step without running anything again.
"""

from __future__ import annotations

from typing import Any, Callable, Optional

from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from std_msgs.msg import Bool

from collres_ros.core.contact_state import ContactStates
from collres_ros.core.pipeline import ResolvedStep
from collres_ros.msg import ContactArray
from collres_ros.ros import names, qos
from collres_ros.srv import GetContacts


class ContactSensing:
    """The in_contact publishers and the get_contacts service of one node."""

    def __init__(self, node: Node, body_names: list[str],
                 contacts_of: Callable[[ResolvedStep], bytes]) -> None:
        """``contacts_of``: a step's ``contacts`` message as published (CDR bytes)."""
        self._node = node
        self._names = list(body_names)
        self._contacts_of = contacts_of
        self._states: Optional[ContactStates] = None
        self._publishers: list[Any] = []
        self._last: Optional[ResolvedStep] = None
        self._service = node.create_service(GetContacts, names.GET_CONTACTS, self._answer)

    def configure(self, enabled: bool, on_impulse: float, off_steps: int) -> None:
        """Start (or restart, with new thresholds: every body out of contact), or stop."""
        if not enabled:
            self._close_publishers()
            self._states = None
            return
        self._states = ContactStates(len(self._names), on_impulse, off_steps)
        if not self._publishers:
            self._publishers = [self._node.create_publisher(
                Bool, names.in_contact_topic(name), qos.latched_qos(),
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
                for name in self._names]
        for publisher in self._publishers:
            publisher.publish(Bool(data=False))

    def step(self, step: ResolvedStep) -> None:
        """Take a resolved step: remembered for the service, states published on change."""
        self._last = step
        if self._states is None:
            return
        for index in self._states.update(step.report):
            self._publishers[index].publish(Bool(data=bool(self._states.in_contact[index])))

    def close(self) -> None:
        self._close_publishers()
        self._node.destroy_service(self._service)

    def _close_publishers(self) -> None:
        for publisher in self._publishers:
            self._node.destroy_publisher(publisher)
        self._publishers = []

    def _answer(self, request: Any, response: Any) -> Any:
        asked = set(request.bodies)
        response.unknown_bodies = sorted(asked - set(self._names))
        step = self._last
        response.stepped = step is not None
        if step is None:
            return response
        array = deserialize_message(self._contacts_of(step), ContactArray)
        response.header = array.header
        response.contacts = [c for c in array.contacts
                             if not asked or c.body_a in asked or c.body_b in asked]
        return response
