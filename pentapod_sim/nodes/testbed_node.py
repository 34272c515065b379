"""
Base class of the testbed's nodes: parameters declared from one :class:`NodeParams` dataclass.

A node class names its parameters with the class attribute ``Params`` (a frozen dataclass of
:func:`pentapod_sim.parameters.param` fields, in a ROS-free module) and finds their typed values
in ``self.params``. :class:`TestbedNode` declares every parameter with its descriptor (type,
description with the unit, range or choices, read-only flag), checks every value the way a
scenario file is checked, and keeps ``self.params`` current when a settable parameter is set.

It sees the overrides given to it (``-p``, ``--params-file``, ``parameter_overrides``) through
rclpy's public API only: it is created with ``automatically_declare_parameters_from_overrides``,
so each override arrives declared; it re-declares its own with their descriptors and undeclares
the others. An override it does not declare is

- ignored if some node kind of the testbed (:data:`pentapod_sim.registry.NODES`) declares it:
  one ``/**`` section of a scenario serves every node (``sample_rate`` reaches the recorder too);
  the scenario runner checks each node's own section strictly before any node starts;
- refused otherwise, with a ConfigError naming the closest parameter of this node.

ROS 2 cannot type an empty list (``[]``) given as an override; rclpy refuses it while the node is
created, and the node says so in one line.
"""
from __future__ import annotations

from typing import Any, ClassVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

from pentapod_sim import registry
from pentapod_sim.errors import ConfigError
from pentapod_sim.parameters import (
    declares,
    help_text,
    kinds_declaring,
    NODE_CLASS,
    NodeParams,
    ROS_NODE_PARAMETERS,
    RosParam,
    summary,
    unknown,
)

_TYPES = {'bool': ParameterType.PARAMETER_BOOL, 'integer': ParameterType.PARAMETER_INTEGER,
          'double': ParameterType.PARAMETER_DOUBLE, 'string': ParameterType.PARAMETER_STRING,
          'bool[]': ParameterType.PARAMETER_BOOL_ARRAY,
          'double[]': ParameterType.PARAMETER_DOUBLE_ARRAY,
          'integer[]': ParameterType.PARAMETER_INTEGER_ARRAY,
          'string[]': ParameterType.PARAMETER_STRING_ARRAY}


def descriptor(param: RosParam) -> ParameterDescriptor:
    """ROS parameter descriptor: type, description with unit, read-only flag, range."""
    desc = ParameterDescriptor(type=_TYPES[param.type], read_only=param.read_only,
                               description=param.full_description(),
                               additional_constraints=param.range)
    if param.bounds is not None and param.type == 'double':
        desc.floating_point_range = [FloatingPointRange(
            from_value=float(param.bounds[0]), to_value=float(param.bounds[1]), step=0.0)]
    elif param.bounds is not None and param.type == 'integer':
        desc.integer_range = [IntegerRange(from_value=int(param.bounds[0]),
                                           to_value=int(param.bounds[1]), step=1)]
    return desc


def _rclpy_own(name: str) -> bool:
    """Parameters rclpy itself declares or reads (use_sim_time, QoS overrides, ...)."""
    return name in ROS_NODE_PARAMETERS or name.startswith('qos_overrides.')


class TestbedNode(Node):
    """
    An rclpy node whose parameters are ``Params``; their typed values are ``self.params``.

    Subclasses set ``Params`` and call ``super().__init__(default_name, **kwargs)`` (the
    keyword arguments of :class:`rclpy.node.Node`: ``cli_args``, ``parameter_overrides``,
    ``context``, ...). ``self.params`` holds the values at start and is replaced when a
    settable parameter is set while the node runs.
    """

    Params: ClassVar[type[NodeParams]] = NodeParams

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        kwargs['automatically_declare_parameters_from_overrides'] = True
        try:
            super().__init__(node_name, **kwargs)
        except ValueError as err:       # rclpy declares every override, and [] has no type
            raise ConfigError(f'node {node_name!r}: a parameter override cannot be declared '
                              f'({err}); an empty list ([]) has no ROS 2 type: leave the '
                              "parameter out (its default) or write [''], [0] or [0.0], "
                              "which mean 'none'") from None
        self._where = f'node {self.get_name()!r}'
        self.params = self._declare_params()
        #: An error that ends the node, raised by its spin loop (:meth:`fail`)
        self.failure: Exception | None = None

    def fail(self, err: Exception) -> None:
        """
        End the node with ``err`` from a callback.

        Raised from a callback, an error reaches the spin loop too, but rclpy's EventsExecutor
        first logs it as FATAL with its traceback; :func:`pentapod_sim.nodes.common.run_node`
        raises ``failure`` after the callback, so the error is one line like every other.
        """
        if self.failure is None:
            self.failure = err

    def param_defaults(self) -> dict[str, Any]:
        """Defaults known only once the node exists (by field name); none by default."""
        return {}

    def _declare_params(self) -> Any:
        cls = type(self).Params
        given = {p.name: p.value for p in self.get_parameters(self.list_parameters([], 0).names)
                 if not _rclpy_own(p.name)}
        others = [name for name in given if not declares(cls, name)]
        for name in others:
            if name != NODE_CLASS and not kinds_declaring(name):
                raise unknown(cls, name, self._where)
        for name in others:             # another node kind's (a shared /** section)
            self.undeclare_parameter(name)
            del given[name]
        if set(others) - {NODE_CLASS}:
            self.get_logger().info(f'ignored (parameters of other node kinds): {others}')
        values = cls.build(given, self._where, self.param_defaults())
        specs = {p.field: p for p in cls.ros_params()}
        for name, value in values.ros_values().items():
            if self.has_parameter(name):
                self.undeclare_parameter(name)
            self.declare_parameter(name, value, descriptor(specs[name.split('.')[0]]),
                                   ignore_override=True)
        self.add_on_set_parameters_callback(self._check_set)
        self.add_post_set_parameters_callback(self._take_set)
        return values

    def _changed(self, changes: list[Parameter]) -> Any:
        """The typed values with ``changes`` applied (ConfigError for a bad one)."""
        values = self.params.ros_values()
        values.update({p.name: p.value for p in changes if declares(type(self).Params, p.name)})
        return type(self).Params.build(values, self._where)

    def _check_set(self, changes: list[Parameter]) -> SetParametersResult:
        """Refuse a new value the parameter's checks refuse (choices, cross-checks)."""
        try:
            self._changed(changes)
        except ConfigError as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _take_set(self, changes: list[Parameter]) -> None:
        old, self.params = self.params, self._changed(changes)
        names = [p.name for p in changes if declares(type(self).Params, p.name)]
        if names:
            self.on_params_changed(old, self.params, names)

    def on_params_changed(self, old: Any, new: Any, names: list[str]) -> None:
        """Hook after settable parameters were set (``old``, ``new``: the typed values)."""
        for name in names:
            self.get_logger().warning(f'parameter {name} changed: '
                                      f'{old.ros_values().get(name)!r} -> '
                                      f'{new.ros_values().get(name)!r}')


def usage(cls: type) -> str:
    """``--help`` text of a node class: usage line, summary and parameters."""
    params = getattr(cls, 'Params', None)
    kind = next((k for k in registry.NODES if k.node.endswith(f':{cls.__qualname__}')), None)
    command = (f'ros2 run pentapod_testbed {kind.name}' if kind is not None else
               f'ros2 run pentapod_testbed component {cls.__module__}:{cls.__qualname__}')
    name = kind.name if kind is not None else cls.__qualname__
    text = f'usage: {command} [--ros-args [-p NAME:=VALUE] ... [--params-file FILE] ...]\n'
    if params is None or not params.ros_params():
        return text
    return (f'{text}\n{name}: {summary(params, whole=True)}\n\n'
            f'parameters (docs/parameters.md):\n{help_text(params)}')
