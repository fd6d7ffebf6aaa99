"""Launch file, RViz config and Foxglove layout: they parse and name only what exists.

``launch`` and ``launch_ros`` are not on PyPI for Jazzy, so the launch file is
checked without running it: it is parsed with ``ast`` and every executable,
launch argument and parameter it names is checked against the package. Where
``launch_ros`` is importable (a ROS install), the description is also built.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest
import yaml

from collres_ros.ros import params

ROOT = Path(__file__).resolve().parents[1]
LAUNCH = ROOT / 'launch' / 'collres.launch.py'
RVIZ = ROOT / 'rviz' / 'collres.rviz'
FOXGLOVE = ROOT / 'foxglove' / 'collres_layout.json'
EXECUTABLES = ('collres_node', 'collres_sim', 'collres_replay', 'collres_demo')
LAUNCH_ARGUMENTS = {'params_file', 'namespace', 'use_sim_time', 'start_sim', 'lifecycle',
                    'autostart', 'clock_topic'}
# `body_markers` is the body-shape MarkerArray of the design's topic table; the viewers
# show it as soon as the node publishes it (same type as contact_markers).
PLANNED_TOPICS = {'/body_markers'}


def node_topics() -> set[str]:
    """Absolute names (root namespace) of the topics collres_node publishes today."""
    from collres_ros.ros import messages
    names = {messages.CORRECTED_STATES, messages.CONTACTS, messages.MARKERS,
             messages.DIAGNOSTICS, 'body_states'}
    return {n if n.startswith('/') else '/' + n for n in names}


def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, 'id', getattr(n.func, 'attr', None)) == name]


def _keyword(call: ast.Call, name: str) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == name), None)


def test_launch_file_names_only_executables_arguments_and_parameters_that_exist() -> None:
    tree = ast.parse(LAUNCH.read_text(), str(LAUNCH))
    defined = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert 'generate_launch_description' in defined
    imports = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert {m.split('.')[0] for m in imports} <= {'launch', 'launch_ros'}, imports

    # the declared arguments: the ARGUMENTS table (name, default, description)
    table = next(n.value for n in tree.body if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], 'id', '') == 'ARGUMENTS')
    declared = {ast.literal_eval(row.elts[0]) for row in table.elts}
    assert declared == LAUNCH_ARGUMENTS
    assert _calls(tree, 'DeclareLaunchArgument'), 'arguments are never declared'
    used = {ast.literal_eval(c.args[0]) for c in _calls(tree, 'LaunchConfiguration')}
    assert used == declared, f'used {used}, declared {declared}'

    # the default params file exists in config/
    default = next(row.elts[1] for row in table.elts
                   if ast.literal_eval(row.elts[0]) == 'params_file')
    parts = [ast.literal_eval(e) for e in default.args[0].elts[1:]]
    assert (ROOT.joinpath(*parts)).is_file(), parts

    constants = {n.targets[0].id: n.value.value for n in tree.body if isinstance(n, ast.Assign)
                 and isinstance(n.targets[0], ast.Name) and isinstance(n.value, ast.Constant)}
    nodes = _calls(tree, 'Node')
    executables = {ast.literal_eval(_keyword(n, 'executable')) for n in nodes}
    assert executables == {'collres_node', 'collres_sim'}
    setup = (ROOT / 'setup.py').read_text()
    cmake = (ROOT / 'CMakeLists.txt').read_text()
    for node in nodes:
        package = _keyword(node, 'package')
        assert (constants.get(package.id) if isinstance(package, ast.Name)
                else ast.literal_eval(package)) == 'collres_ros'
        exe = ast.literal_eval(_keyword(node, 'executable'))
        assert exe in EXECUTABLES and f"'scripts/{exe}'" in setup
        assert f'scripts/{exe}' in cmake, f'{exe} is not installed by CMake'
        assert ast.literal_eval(_keyword(node, 'name')) == exe
        # command-line flags given to an executable are flags its main knows
        flags = _keyword(node, 'arguments')
        # the main, and the module it runs when the main is a thin wrapper (ros/node.py)
        module = f'{exe[len("collres_"):]}.py'
        paths = (ROOT / 'collres_ros' / module, ROOT / 'collres_ros' / 'ros' / module)
        main = ''.join(path.read_text() for path in paths if path.is_file())
        for flag in ([] if flags is None else ast.literal_eval(flags)):
            assert f"'{flag}'" in main, f'{exe} has no flag {flag}'
        # every parameter given as a dict is one the node declares (or a ROS builtin)
        known = {s.name for s in params.all_specs()} | set(params.ROS_BUILTIN)
        for item in _keyword(node, 'parameters').elts:
            if isinstance(item, ast.Dict):
                keys = {ast.literal_eval(k) for k in item.keys}
                assert keys <= known, keys - known
    sim = next(n for n in nodes if ast.literal_eval(_keyword(n, 'executable')) == 'collres_sim')
    assert _keyword(sim, 'condition') is not None, 'collres_sim must be optional'


def test_the_lifecycle_variant_is_a_lifecycle_node_and_each_scene_can_have_its_clock() -> None:
    tree = ast.parse(LAUNCH.read_text(), str(LAUNCH))
    managed = _calls(tree, 'LifecycleNode')
    assert len(managed) == 1, 'lifecycle:=true starts a launch_ros LifecycleNode'
    assert ast.literal_eval(_keyword(managed[0], 'arguments')) == ['--lifecycle']
    assert ast.literal_eval(_keyword(managed[0], 'executable')) == 'collres_node'
    changes = [ast.literal_eval(_keyword(c, 'transition_id')) if isinstance(
        _keyword(c, 'transition_id'), ast.Constant) else _keyword(c, 'transition_id').id
        for c in _calls(tree, 'ChangeState')]
    assert sorted(changes) == ['TRANSITION_ACTIVATE', 'TRANSITION_CONFIGURE']
    assert _calls(tree, 'OnStateTransition'), 'activate once configured (autostart)'
    # the clock: one remap of /clock, on every node
    for call in _calls(tree, 'Node') + managed:
        assert getattr(_keyword(call, 'remappings'), 'id', None) == 'clock'
    clock = next(n.value for n in ast.walk(tree) if isinstance(n, ast.Assign)
                 and getattr(n.targets[0], 'id', '') == 'clock')
    assert ast.literal_eval(clock.elts[0].elts[0]) == '/clock'


def test_launch_file_builds_a_description_where_launch_ros_exists() -> None:
    pytest.importorskip('launch_ros')
    import importlib.util
    spec = importlib.util.spec_from_file_location('collres_launch', LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    names = {a.name for a in description.get_launch_arguments()}
    assert names == LAUNCH_ARGUMENTS


def _rviz_topics(node: object) -> set[str]:
    found: set[str] = set()
    if isinstance(node, dict):
        topic = node.get('Topic')
        if isinstance(topic, dict) and 'Value' in topic:
            found.add(topic['Value'])
        elif isinstance(topic, str):
            found.add(topic)
        for value in node.values():
            found |= _rviz_topics(value)
    elif isinstance(node, list):
        for value in node:
            found |= _rviz_topics(value)
    return found


def test_rviz_config_parses_and_shows_the_markers_in_the_world_frame() -> None:
    config = yaml.safe_load(RVIZ.read_text())
    manager = config['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == params.SCENE_PARAMS[0].default == 'world'
    displays = {d['Name']: d for d in manager['Displays']}
    assert displays['Contact markers']['Class'] == 'rviz_default_plugins/MarkerArray'
    assert displays['Body markers']['Class'] == 'rviz_default_plugins/MarkerArray'
    topics = _rviz_topics(manager)
    print('rviz topics:', sorted(topics))
    assert topics == {'/contact_markers', '/body_markers'}
    assert topics <= node_topics() | PLANNED_TOPICS


def _foxglove_topics(config: dict) -> set[str]:
    found: set[str] = set()
    for panel in config['configById'].values():
        found |= set(panel.get('topics', {}))
        for key in ('topicToRender', 'topicPath'):
            if key in panel:
                found.add(panel[key])
        for path in panel.get('paths', []):
            found.add(path['value'])
    # a message path is `/topic.field...`: the topic ends before the first '.'
    return {re.split(r'[.{]', t, maxsplit=1)[0] for t in found}


def test_foxglove_layout_parses_and_names_existing_topics() -> None:
    config = json.loads(FOXGLOVE.read_text())
    panels = config['configById']
    kinds = {key.split('!')[0] for key in panels}
    assert {'3D', 'DiagnosticSummary', 'DiagnosticStatusPanel', 'Plot'} <= kinds

    def leaves(node: object) -> set[str]:
        if isinstance(node, str):
            return {node}
        return leaves(node['first']) | leaves(node['second'])
    assert leaves(config['layout']) == set(panels), 'a panel is configured but not laid out'
    three_d = next(v for k, v in panels.items() if k.startswith('3D!'))
    assert three_d['followTf'] == 'world'
    topics = _foxglove_topics(config)
    print('foxglove topics:', sorted(topics))
    assert {'/contact_markers', '/body_markers', '/diagnostics'} <= topics
    assert topics <= node_topics() | PLANNED_TOPICS


def test_cmake_installs_the_viewing_files_to_share() -> None:
    cmake = (ROOT / 'CMakeLists.txt').read_text()
    line = next(ln for ln in cmake.splitlines() if 'DESTINATION share' in ln
                and 'launch' in ln)
    for directory in ('launch', 'rviz', 'foxglove'):
        assert directory in line.split() and (ROOT / directory).is_dir()
