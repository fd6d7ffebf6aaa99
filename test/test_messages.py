"""The package's interfaces: import next to the hand-written modules, serialise, cross DDS."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from collres_ros.msg import BodyState, BodyStateArray, Contact, ContactArray


def _contact_array() -> ContactArray:
    msg = ContactArray()
    msg.header.frame_id = 'world'
    msg.header.stamp.sec = 12
    msg.header.stamp.nanosec = 345_000_000
    contact = Contact()
    contact.body_a, contact.body_b = 'floor', 'ball'
    contact.position.x, contact.position.y, contact.position.z = 0.5, -0.25, 0.0
    contact.normal.z = 1.0
    contact.depth = 0.00125
    contact.time_of_impact.sec, contact.time_of_impact.nanosec = 12, 340_000_000
    contact.normal_impulse = 3.5
    contact.friction_impulse.x = -0.75
    contact.state = Contact.SLIDING
    msg.contacts = [contact, Contact(body_a='box', body_b='ball', state=Contact.IMPACT)]
    return msg


def test_hand_written_and_generated_modules_share_the_package() -> None:
    import collres_ros.core.types as types
    import collres_ros.msg as msg
    assert Path(msg.__file__).parent.parent == Path(types.__file__).parent.parent
    # the message constants equal the core's ContactState values
    assert [Contact.IMPACT, Contact.RESTING, Contact.SLIDING, Contact.STICKING,
            Contact.SLEEPING] == [
        int(s) for s in types.ContactState]


def test_body_state_array_round_trips_through_cdr() -> None:
    msg = BodyStateArray()
    msg.header.frame_id = 'world'
    for i, name in enumerate(('ball', 'box')):
        body = BodyState(name=name)
        body.pose.position.z = 1.0 + i
        body.pose.orientation.w = math.cos(0.3)
        body.pose.orientation.z = math.sin(0.3)
        body.twist.linear.x = -2.5
        body.twist.angular.y = 7.0
        msg.bodies.append(body)
    back = deserialize_message(serialize_message(msg), BodyStateArray)
    assert back == msg
    assert [b.name for b in back.bodies] == ['ball', 'box']
    assert back.bodies[1].pose.position.z == 2.0


def test_contact_array_round_trips_through_cdr() -> None:
    msg = _contact_array()
    back = deserialize_message(serialize_message(msg), ContactArray)
    assert back == msg
    assert back.contacts[0].state == Contact.SLIDING == 3
    assert back.contacts[0].friction_impulse.x == -0.75


PUBLISHER = textwrap.dedent('''
    import sys, time
    import rclpy
    from collres_ros.msg import ContactArray, Contact
    rclpy.init()
    node = rclpy.create_node('contact_publisher')
    pub = node.create_publisher(ContactArray, 'contacts', 10)
    msg = ContactArray()
    msg.header.frame_id = 'world'
    msg.contacts = [Contact(body_a='floor', body_b='ball', normal_impulse=4.25,
                            state=Contact.RESTING)]
    deadline = time.monotonic() + 60.0
    while rclpy.ok() and time.monotonic() < deadline:
        pub.publish(msg)
        rclpy.spin_once(node, timeout_sec=0.05)
''')


@pytest.mark.slow
def test_contact_array_travels_between_processes_over_dds(ros_domain: int) -> None:
    import rclpy
    from rclpy.node import Node

    publisher = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=dict(os.environ),
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Node('contact_listener', context=context)
        received: list[ContactArray] = []
        node.create_subscription(ContactArray, 'contacts', received.append, 10)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 30.0
        while not received and time.monotonic() < deadline and publisher.poll() is None:
            executor.spin_once(timeout_sec=0.1)
        assert received, 'no ContactArray arrived within 30 s'
        contact = received[0].contacts[0]
        assert (contact.body_a, contact.body_b, contact.normal_impulse) == ('floor', 'ball', 4.25)
        assert contact.state == Contact.RESTING
        types = dict(node.get_topic_names_and_types())
        assert types['/contacts'] == ['collres_ros/msg/ContactArray']
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
        publisher.terminate()
        publisher.wait(timeout=10)
