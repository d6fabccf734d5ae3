"""A port of the JSON-schema parser of the open-source Foxglove Studio (the one Lichtblick ships:
``packages/mcap-support/src/parseJsonSchema.ts``, MPL-2.0), written here from its behaviour so the
tests can hold our channels' schemas to it without Node.

It turns a channel's JSON schema into the datatypes the plot and raw-message panels offer, and it
throws on what it does not know; the panels of a channel whose schema throws stay empty.  What it
accepts: an object with ``properties`` whose fields are boolean, string (plain or base64
``contentEncoding``), number, integer, a nested object (recursively), or an array whose ``items`` are
one of those.  What it refuses: a union type such as ``["number", "null"]``, ``null``, an object
without ``properties``, an array without ``items`` or of arrays, another ``contentEncoding``.
"""

from __future__ import annotations


class UnsupportedSchema(Exception):
    pass


def parse_json_schema(schema: dict, type_name: str) -> dict[str, list[dict]]:
    """The datatypes (type name -> fields) Foxglove derives from ``schema``; raises UnsupportedSchema
    with the message Foxglove's parser gives where it would throw."""
    datatypes: dict[str, list[dict]] = {}

    def add(s: dict, name: str) -> None:
        if s.get("type") != "object":
            raise UnsupportedSchema(f'Expected "type": "object" for schema {name}, got {s.get("type")!r}')
        props = s.get("properties")
        if not isinstance(props, dict):     # Object.entries(undefined) throws a TypeError there
            raise UnsupportedSchema(f"schema {name} has no properties")
        fields = []
        for field, fs in props.items():
            t = fs.get("type")
            if t == "boolean":
                fields.append({"name": field, "type": "bool"})
            elif t == "string":
                enc = fs.get("contentEncoding")
                if enc is None:
                    fields.append({"name": field, "type": "string"})
                elif enc == "base64":
                    fields.append({"name": field, "type": "uint8", "isArray": True})
                else:
                    raise UnsupportedSchema(f"Unsupported contentEncoding {enc!r}")
            elif t in ("number", "integer"):
                fields.append({"name": field, "type": "float64"})
            elif t == "object":
                add(fs, f"{name}.{field}")
                fields.append({"name": field, "type": f"{name}.{field}", "isComplex": True})
            elif t == "array":
                items = fs.get("items")
                if not isinstance(items, dict):     # itemSchema.type on undefined throws there
                    raise UnsupportedSchema(f"array field {field} has no items")
                it = items.get("type")
                if it == "boolean":
                    fields.append({"name": field, "type": "bool", "isArray": True})
                elif it == "string":
                    if items.get("contentEncoding") is not None:
                        raise UnsupportedSchema(f"Unsupported contentEncoding {items['contentEncoding']!r} for array item")
                    fields.append({"name": field, "type": "string", "isArray": True})
                elif it in ("number", "integer"):
                    fields.append({"name": field, "type": "float64", "isArray": True})
                elif it == "object":
                    add(items, f"{name}.{field}")
                    fields.append({"name": field, "type": f"{name}.{field}", "isComplex": True, "isArray": True})
                else:
                    raise UnsupportedSchema(f"Unsupported array item type: {it!r}")
            else:
                raise UnsupportedSchema(f"Unsupported object field type for {field}: {t!r}")
        datatypes[name] = fields

    add(schema, type_name)
    return datatypes
