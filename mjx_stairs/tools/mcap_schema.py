"""JSON schemas of the MCAP topics (tools.mcap_log): Foxglove's well-known types and ours."""

from __future__ import annotations

from typing import Any

from mjx_stairs.sim import robot as rb

# ----------------------------------------------------------------------------- JSON schemas
# The fields of Foxglove's message schemas (github.com/foxglove/schemas, schemas/jsonschema),
# composed from small parts.


def _obj(title: str, props: dict[str, Any], description: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {"title": title, "type": "object", "properties": props}
    if description:
        out["description"] = description
    return out


def _num() -> dict[str, str]:
    return {"type": "number"}


def _time() -> dict[str, Any]:
    return {
        "type": "object",
        "title": "time",
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
        },
    }


def _vec3() -> dict[str, Any]:
    return _obj("foxglove.Vector3", {"x": _num(), "y": _num(), "z": _num()})


def _quat() -> dict[str, Any]:
    return _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})


def _pose() -> dict[str, Any]:
    return _obj("foxglove.Pose", {"position": _vec3(), "orientation": _quat()})


def _color() -> dict[str, Any]:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _point3() -> dict[str, Any]:
    return _obj("foxglove.Point3", {"x": _num(), "y": _num(), "z": _num()})


def _array(items: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": items}


def _frame_transform() -> dict[str, Any]:
    return _obj(
        "foxglove.FrameTransform",
        {
            "timestamp": _time(),
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _vec3(),
            "rotation": _quat(),
        },
        "A transform between two reference frames in 3D space",
    )


def _scene_entity() -> dict[str, Any]:
    shape = lambda title: _obj(title, {"pose": _pose(), "size": _vec3(), "color": _color()})
    cylinder = _obj(
        "foxglove.CylinderPrimitive",
        {"pose": _pose(), "size": _vec3(), "bottom_scale": _num(), "top_scale": _num(),
         "color": _color()},
    )
    triangles = _obj(
        "foxglove.TriangleListPrimitive",
        {"pose": _pose(), "points": _array(_point3()), "color": _color(),
         "colors": _array(_color()), "indices": _array({"type": "integer", "minimum": 0})},
    )
    return _obj(
        "foxglove.SceneEntity",
        {
            "timestamp": _time(),
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": {"type": "object", "title": "duration",
                         "properties": {"sec": {"type": "integer"},
                                        "nsec": {"type": "integer", "minimum": 0,
                                                 "maximum": 999999999}}},
            "frame_locked": {"type": "boolean"},
            "metadata": _array(_obj("foxglove.KeyValuePair",
                                    {"key": {"type": "string"}, "value": {"type": "string"}})),
            "cubes": _array(shape("foxglove.CubePrimitive")),
            "spheres": _array(shape("foxglove.SpherePrimitive")),
            "cylinders": _array(cylinder),
            "triangles": _array(triangles),
        },
        "A visual element in a 3D scene",
    )


def _floats(n: int | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {"type": "array", "items": {"type": "number"}}
    if n is not None:
        out.update(minItems=n, maxItems=n)
    return out


SCHEMAS: dict[str, dict[str, Any]] = {
    "foxglove.FrameTransforms": _obj(
        "foxglove.FrameTransforms", {"transforms": _array(_frame_transform())},
        "An array of FrameTransform messages",
    ),
    "foxglove.SceneUpdate": _obj(
        "foxglove.SceneUpdate",
        {
            "deletions": _array(_obj("foxglove.SceneEntityDeletion",
                                     {"timestamp": _time(), "type": {"type": "integer"},
                                      "id": {"type": "string"}})),
            "entities": _array(_scene_entity()),
        },
        "An update to the entities displayed in a 3D scene",
    ),
    "foxglove.PoseInFrame": _obj(
        "foxglove.PoseInFrame",
        {"timestamp": _time(), "frame_id": {"type": "string"}, "pose": _pose()},
        "A timestamped pose for an object or reference frame in 3D space",
    ),
    "foxglove.PosesInFrame": _obj(
        "foxglove.PosesInFrame",
        {"timestamp": _time(), "frame_id": {"type": "string"}, "poses": _array(_pose())},
        "An array of timestamped poses for an object or reference frame in 3D space",
    ),
    "foxglove.Grid": _obj(
        "foxglove.Grid",
        {
            "timestamp": _time(),
            "frame_id": {"type": "string"},
            "pose": _pose(),
            "column_count": {"type": "integer", "minimum": 0},
            "cell_size": _obj("foxglove.Vector2", {"x": _num(), "y": _num()}),
            "row_stride": {"type": "integer", "minimum": 0},
            "cell_stride": {"type": "integer", "minimum": 0},
            "fields": _array(_obj("foxglove.PackedElementField",
                                  {"name": {"type": "string"},
                                   "offset": {"type": "integer", "minimum": 0},
                                   "type": {"type": "integer"}})),
            "data": {"type": "string", "contentEncoding": "base64"},
        },
        "A 2D grid of data",
    ),
    "mjx_stairs.JointState": _obj(
        "mjx_stairs.JointState",
        {"timestamp": _time(), "name": _array({"type": "string"}), "position": _floats(12),
         "velocity": _floats(12), "effort": _floats(12)},
        "Joint positions (rad), velocities (rad/s) and torques (N m) in JOINT_NAMES order",
    ),
    "mjx_stairs.FootContacts": _obj(
        "mjx_stairs.FootContacts",
        {"timestamp": _time(), **{leg: {"type": "boolean"} for leg in rb.LEGS}},
        "Whether each foot sphere touches the terrain",
    ),
    "mjx_stairs.Action": _obj(
        "mjx_stairs.Action",
        {"timestamp": _time(), "action": _floats(12), "q_target": _floats(12)},
        "Policy action (clipped as applied) and PD target q_nominal + action_scale * action",
    ),
    "mjx_stairs.Status": _obj(
        "mjx_stairs.Status",
        {"timestamp": _time(), "done": {"type": "boolean"}, "terminated": {"type": "boolean"},
         "success": {"type": "boolean"}, "goal_distance": _num(),
         "episode_step": {"type": "integer"}, "tile": {"type": "integer"}},
        "Episode status after the step (done: the episode ended and the robot was reset)",
    ),
}


def reward_schema(terms: list[str]) -> dict[str, Any]:
    return _obj(
        "mjx_stairs.Reward",
        {"timestamp": _time(), "total": _num(), **{t: _num() for t in terms}},
        "Reward of the step: total and each term, already weighted and times dt",
    )
