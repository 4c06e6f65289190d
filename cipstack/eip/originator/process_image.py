"""A class 1 connection's data as the caller sees it: fields by name when the assembly's schema is
known, raw bytes always. Shared by the asyncio and the blocking class 1 shells (no I/O here)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ...errors import BadRequest, ReadOnlyField, UnknownField

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema


class ProcessImage:
    """Assembly data with field access when the schema is known, raw bytes always.

    ``image.speed_reference`` reads a field, ``image.speed_reference = 900`` writes one (outputs
    only), ``image.fields()`` decodes them all, ``image.raw`` is the bytes. A field the schema
    does not have raises ``AttributeError`` naming the schema and its fields, or why none is known.
    """

    _buffer: bytearray
    _schema: AssemblySchema | None
    _writable: bool
    _where: str

    def __init__(self, buffer: bytearray, schema: AssemblySchema | None, writable: bool, where: str = "") -> None:
        object.__setattr__(self, "_buffer", buffer)
        object.__setattr__(self, "_schema", schema)
        object.__setattr__(self, "_writable", writable)
        object.__setattr__(self, "_where", where)

    @property
    def raw(self) -> bytes:
        return bytes(self._buffer)

    @raw.setter
    def raw(self, value: bytes) -> None:
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        if len(value) != len(self._buffer):
            raise BadRequest(f"assembly is {len(self._buffer)} bytes, got {len(value)}")
        self._buffer[:] = value

    @property
    def schema(self) -> AssemblySchema | None:
        """The assembly's declaration (None: raw bytes only)."""
        return self._schema

    @property
    def field_names(self) -> frozenset[str]:
        """The fields this image has by name (empty when no schema is known)."""
        return self._schema.field_names if self._schema is not None else frozenset()

    def fields(self) -> dict[str, Any]:
        """Every field's value by name."""
        if self._schema is None:
            raise UnknownField(self._no_field(None))
        return self._schema.decode(bytes(self._buffer))

    def _no_field(self, name: str | None) -> str:
        what = f"no field {name!r}" if name is not None else "no field names"
        schema = self._schema
        if schema is None:
            why = self._where or "no assembly schema known"
            return f"{what}: {why} (use .raw)"
        where = self._where or f"assembly {schema.instance} {schema.name!r}"
        return f"{what} in {where}; its fields: {', '.join(f.name for f in schema.fields)}"

    def __getattr__(self, name: str) -> Any:
        schema = self._schema
        if name.startswith("__") or schema is None or name not in schema.field_names:
            if name.startswith("__"):
                raise AttributeError(name)
            raise UnknownField(self._no_field(name))
        return schema.decode(bytes(self._buffer))[name]

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "raw":
            ProcessImage.raw.fset(self, value)  # type: ignore[attr-defined]
            return
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        if self._schema is None or name not in self._schema.field_names:
            raise UnknownField(self._no_field(name))
        self._buffer[:] = self._schema.with_field(bytes(self._buffer), name, value)

    def update(self, **values: Any) -> None:
        """Set several fields at once (``io.output.update(run_forward=True, speed_reference=900)``)."""
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        schema = self._schema
        for name in values:
            if schema is None or name not in schema.field_names:
                raise UnknownField(self._no_field(name))
        data = bytes(self._buffer)
        for name, value in values.items():
            assert schema is not None   # every name was checked above
            data = schema.with_field(data, name, value)
        self._buffer[:] = data  # one assignment: a production sees all the fields or none

    def __repr__(self) -> str:
        if self._schema is None:
            return f"ProcessImage(raw={self.raw.hex()!r})"
        return "ProcessImage(" + ", ".join(f"{k}={v!r}" for k, v in self.fields().items()) + ")"


__all__ = ["ProcessImage"]
