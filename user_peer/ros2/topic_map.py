"""A topic map from a YAML file (``robofabric ros2 --topic-map FILE``): rename the bridge's topics, set their QoS,
and allow or deny them, the way a launch file's remaps and a QoS override file would, in one place a class keeps.

.. code-block:: yaml

    rename:                      # the bridge's name -> the name on ROS 2
      /base1/scan: /scan
      /base1/cmd_vel: /cmd_vel
    qos:                         # per topic (the bridge's name): any of reliability, durability, depth
      /base1/scan: {reliability: reliable, depth: 10}
    allow: [/base1/*, /map, /clock, /tf*]   # only these (shell patterns); absent: all
    deny: [/object/*]            # never these (deny wins over allow)

Names are the bridge's own, as docs/ros2.md lists them (under ``/NS`` with ``--namespace``), outgoing and incoming
alike: a denied command topic is not subscribed to, a denied stream not published (nothing is built for it, a
sonar transducer's Range included). A rename changes the name only; the frame ids stay (``--namespace`` prefixes
those). ``--ros-args -r`` remaps work as well, after this map (rclpy applies them to the renamed names).

A file that does not read as such a map is refused at start with what is wrong and where (:class:`TopicMapError`):
an unknown section, a name that is not an absolute ROS name, an unknown QoS field or value.

:class:`MappedNode` applies the map: it stands for the rclpy node wherever the bridge makes a publisher or a
subscription, and hands everything else to the node.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import yaml
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.validate_topic_name import validate_topic_name

__all__ = ["TopicMap", "TopicMapError", "MappedNode", "is_off", "load_topic_map", "parse_topic_map"]

_SECTIONS = ("rename", "qos", "allow", "deny")
_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE, "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}


class TopicMapError(ValueError):
    """A topic map that cannot be used; the message says what is wrong and where."""


@dataclass(frozen=True, slots=True)
class TopicMap:
    """What the file says: ``rename`` (name -> name), ``qos`` (name -> fields), ``allow``/``deny`` (patterns)."""

    rename: dict[str, str] = field(default_factory=dict)
    qos: dict[str, dict[str, Any]] = field(default_factory=dict)
    allow: tuple[str, ...] | None = None
    deny: tuple[str, ...] = ()

    def name(self, topic: str) -> str | None:
        """The ROS name of the bridge's ``topic``; None when the map keeps it off ROS."""
        if any(fnmatch.fnmatchcase(topic, p) for p in self.deny):
            return None
        if self.allow is not None and not any(fnmatch.fnmatchcase(topic, p) for p in self.allow):
            return None
        return self.rename.get(topic, topic)

    def summary(self) -> str:
        """One line for the bridge's start: what the map does."""
        parts = [f"{len(self.rename)} renamed", f"QoS set for {len(self.qos)}"]
        if self.allow is not None:
            parts.append(f"only {', '.join(self.allow)}")
        if self.deny:
            parts.append(f"never {', '.join(self.deny)}")
        return ", ".join(parts)

    def profile(self, topic: str, qos: Any) -> Any:
        """``qos`` (a QoSProfile or a depth) with the map's fields for ``topic`` put over it."""
        over = self.qos.get(topic)
        if not over:
            return qos
        base = QoSProfile(depth=qos) if isinstance(qos, int) else qos
        return QoSProfile(
            history=base.history,
            depth=over.get("depth", base.depth),
            reliability=over.get("reliability", base.reliability),
            durability=over.get("durability", base.durability),
        )


def _name(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value.startswith("/"):
        raise TopicMapError(f"{where}: {value!r} is not an absolute topic name (e.g. /base1/scan)")
    try:
        validate_topic_name(value)
    except Exception as exc:  # rclpy's InvalidTopicNameException says which character
        raise TopicMapError(f"{where}: {value!r} is not a ROS topic name: {str(exc).splitlines()[0]}") from None
    return value


def _qos(fields: Any, where: str) -> dict[str, Any]:
    if not isinstance(fields, dict):
        raise TopicMapError(f"{where}: give a mapping of reliability, durability, depth, got {fields!r}")
    out: dict[str, Any] = {}
    for k, v in fields.items():
        table = {"reliability": _RELIABILITY, "durability": _DURABILITY}.get(k)
        if table is not None:
            if v not in table:
                raise TopicMapError(f"{where}: {k} {v!r} is not one of {', '.join(table)}")
            out[k] = table[v]
        elif k == "depth":
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= 10_000:
                raise TopicMapError(f"{where}: depth {v!r} is not a whole number from 1 to 10000")
            out[k] = v
        else:
            raise TopicMapError(f"{where}: unknown QoS field {k!r} (reliability, durability, depth)")
    return out


def _patterns(value: Any, where: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(p, str) and p.startswith("/") for p in value):
        raise TopicMapError(f"{where}: give a list of absolute topic names or shell patterns (e.g. [/base1/*])")
    return tuple(value)


def parse_topic_map(data: Any, where: str = "topic map") -> TopicMap:
    """The map a parsed YAML document holds; :class:`TopicMapError` naming what is wrong."""
    if data is None:
        return TopicMap()
    if not isinstance(data, dict):
        raise TopicMapError(f"{where}: the file holds {type(data).__name__}, not a mapping of {', '.join(_SECTIONS)}")
    unknown = sorted(set(data) - set(_SECTIONS))
    if unknown:
        raise TopicMapError(f"{where}: unknown section {unknown[0]!r} (the sections: {', '.join(_SECTIONS)})")
    rename, qos = data.get("rename") or {}, data.get("qos") or {}
    if not isinstance(rename, dict) or not isinstance(qos, dict):
        raise TopicMapError(f"{where}: rename and qos map topic names to a name and to QoS fields")
    renamed = {_name(k, f"{where}, rename"): _name(v, f"{where}, rename {k}") for k, v in rename.items()}
    targets = list(renamed.values())
    twice = sorted({t for t in targets if targets.count(t) > 1})
    if twice:
        raise TopicMapError(f"{where}: rename gives {twice[0]!r} to two topics")
    return TopicMap(
        renamed,
        {_name(k, f"{where}, qos"): _qos(v, f"{where}, qos {k}") for k, v in qos.items()},
        _patterns(data["allow"], f"{where}, allow") if data.get("allow") is not None else None,
        _patterns(data.get("deny") or [], f"{where}, deny"),
    )


def load_topic_map(path: str | Path) -> TopicMap:
    """The map in YAML file ``path``; :class:`TopicMapError` when it cannot be read or used."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise TopicMapError(f"topic map {path}: {exc.strerror or exc}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise TopicMapError(f"topic map {path}: not YAML: {' '.join(str(exc).split())}") from None
    return parse_topic_map(data, f"topic map {path}")


class _Off:
    """A publisher or subscription the map keeps off ROS: publishing does nothing, nobody listens."""

    def publish(self, msg: Any) -> None:
        pass

    def get_subscription_count(self) -> int:
        return 0


def is_off(pub: Any) -> bool:
    """Whether ``pub`` is one the map kept off ROS (the bridge then builds no message for it)."""
    return isinstance(pub, _Off)


class MappedNode:
    """``node`` with ``topic_map`` applied to the publishers and subscriptions made through it; ``off`` counts the
    topics the map kept off ROS."""

    def __init__(self, node: Any, topic_map: TopicMap) -> None:
        self.rcl_node = node
        self.topic_map = topic_map
        self.off: set[str] = set()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.rcl_node, name)

    def _made(self, make: Callable[..., Any], cls: type, topic: str, qos: Any, *args: Any) -> Any:
        name = self.topic_map.name(topic)
        if name is None:
            self.off.add(topic)
            return _Off()
        return make(cls, name, *args, self.topic_map.profile(topic, qos))

    def create_publisher(self, cls: type, topic: str, qos: Any) -> Any:
        return self._made(self.rcl_node.create_publisher, cls, topic, qos)

    def create_subscription(self, cls: type, topic: str, callback: Callable[[Any], None], qos: Any) -> Any:
        return self._made(self.rcl_node.create_subscription, cls, topic, qos, callback)

    def destroy_publisher(self, pub: Any) -> None:
        if not isinstance(pub, _Off):
            self.rcl_node.destroy_publisher(pub)

    def destroy_subscription(self, sub: Any) -> None:
        if not isinstance(sub, _Off):
            self.rcl_node.destroy_subscription(sub)
