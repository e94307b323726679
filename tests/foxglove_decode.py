"""Decoding Foxglove's protobuf messages from the schema a server or a file gives (a
FileDescriptorSet), with Google's protobuf runtime: nothing of foxglove-sdk's own classes."""

from __future__ import annotations

import math
from typing import Any

from google.protobuf.descriptor_pb2 import FileDescriptorProto, FileDescriptorSet
from google.protobuf.descriptor_pool import DescriptorPool
from google.protobuf.message_factory import GetMessageClass


def message_class(schema_name: str, file_descriptor_set: bytes) -> Any:
    """The protobuf message class named ``schema_name`` (``foxglove.SceneUpdate``) in a
    serialised FileDescriptorSet."""
    fds = FileDescriptorSet.FromString(file_descriptor_set)
    pool = DescriptorPool()
    pending = {fd.name: fd for fd in fds.file}

    def add(fd: FileDescriptorProto) -> None:
        for dep in fd.dependency:
            if dep in pending:
                add(pending.pop(dep))
        pool.Add(fd)

    while pending:
        add(pending.popitem()[1])
    return GetMessageClass(pool.FindMessageTypeByName(schema_name))


def metadata(entity: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in entity.metadata}


def rotate_x(q: Any) -> tuple[float, float, float]:
    """The unit x axis turned by the protobuf Quaternion ``q`` (x, y, z, w)."""
    w, x, y, z = q.w, q.x, q.y, q.z
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return (1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y))
