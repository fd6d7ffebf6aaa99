"""Names that users, launch files and bags see: topic names and contact state names.

Topic names are relative (the node publishes them in its namespace, so
namespaces and remaps work); ``absolute`` gives the name a bag records.
"""

from __future__ import annotations

from collres_ros.core.types import ContactState

# --- topics -----------------------------------------------------------------------------------

STATES = 'body_states'                      # in: BodyStateArray, one step per message
CORRECTED_STATES = 'body_states/corrected'  # out: BodyStateArray
CONTACTS = 'contacts'                       # out: ContactArray
MARKERS = 'contact_markers'                 # out: MarkerArray
BODY_MARKERS = 'body_markers'               # out: MarkerArray, each body's shape
TF = '/tf'                                  # out (publish_tf) and in (robot links): TFMessage
TF_STATIC = '/tf_static'                    # in (robot links): tf2_msgs/TFMessage, latched
DIAGNOSTICS = '/diagnostics'                # out: DiagnosticArray (absolute: diagnostic_updater)
CLOCK = '/clock'                            # sim out: rosgraph_msgs/Clock
GET_CONTACTS = 'get_contacts'               # service: GetContacts, the last step's contacts
ROBOT_DESCRIPTION = 'robot_description'     # in: std_msgs/String, the URDF (transient local)


BODIES = 'bodies/'   # the per-body topics' prefix


def pose_topic(name: str, corrected: bool = False) -> str:
    """``bodies/<name>/pose`` (input) or ``bodies/<name>/pose/corrected`` (output)."""
    return f'{BODIES}{name}/pose' + ('/corrected' if corrected else '')


def twist_topic(name: str, corrected: bool = False) -> str:
    """``bodies/<name>/twist`` (input) or ``bodies/<name>/twist/corrected`` (output)."""
    return f'{BODIES}{name}/twist' + ('/corrected' if corrected else '')


def wrench_topic(name: str) -> str:
    """``bodies/<name>/contact_wrench`` (output, WrenchStamped)."""
    return f'{BODIES}{name}/contact_wrench'


def in_contact_topic(name: str) -> str:
    """``bodies/<name>/in_contact`` (output, std_msgs/Bool, with ``contact_state``)."""
    return f'{BODIES}{name}/in_contact'


def output_topics(body_names: list[str]) -> list[str]:
    """Every topic collres_node can publish for a scene of ``body_names``, as it names them."""
    per_body = [topic for name in body_names
                for topic in (pose_topic(name, True), twist_topic(name, True), wrench_topic(name))]
    return [CORRECTED_STATES, CONTACTS, MARKERS, BODY_MARKERS, TF, DIAGNOSTICS] + per_body


def absolute(topic: str, namespace: str = '/') -> str:
    """Absolute name of a relative topic in ``namespace`` ('/' or '/robot'), as bags name it."""
    if topic.startswith('/'):
        return topic
    return namespace.rstrip('/') + '/' + topic


# --- contact states ---------------------------------------------------------------------------

# Contact.state value -> name (the Contact.msg constants), in value order.
STATE_NAMES = {int(state): state.name for state in ContactState}


def state_name(value: int) -> str:
    """Name of a Contact.state value ('IMPACT', ...), or the number itself when unknown."""
    return STATE_NAMES.get(int(value), str(int(value)))
