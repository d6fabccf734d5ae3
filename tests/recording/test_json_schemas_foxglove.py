"""Every JSON schema our recordings and live view declare is one Foxglove's own JSON-schema parser
accepts (a port of it: tests/foxglove_json_schema.py).  Before, the nullable fields were union types
(``["number", "null"]``) on /detections, /head, /commands, /truth and the daemon's /metrics, which
that parser refuses ("Unsupported object field type for xyz_m: ['array', 'null']"), so the shipped
layout's plots stayed empty in Foxglove Studio's open-source line (Lichtblick)."""

import json
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from foveatrack.recording.format import RECORD_SCHEMAS, json_schema_of

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from foxglove_json_schema import UnsupportedSchema, parse_json_schema  # noqa: E402


def test_the_port_refuses_what_foxglove_refuses():
    # the port must be able to fail: the old nullable declaration, null, a bare object, a bare array
    for field in ({"type": ["number", "null"]}, {"type": ["array", "null"], "items": {"type": "number"}},
                  {"type": "null"}, {"type": "object"}, {"type": "array"},
                  {"type": "array", "items": {"type": "array", "items": {"type": "number"}}}):
        with pytest.raises(UnsupportedSchema):
            parse_json_schema({"type": "object", "properties": {"f": field}}, "T")
    ok = parse_json_schema({"type": "object", "properties": {
        "a": {"type": "number"}, "b": {"type": "array", "items": {"type": "integer"}},
        "c": {"type": "object", "properties": {"d": {"type": "string", "contentEncoding": "base64"}}}}}, "T")
    assert ok["T"][1] == {"name": "b", "type": "float64", "isArray": True}
    assert ok["T.c"] == [{"name": "d", "type": "uint8", "isArray": True}]


@pytest.mark.parametrize("channel", sorted(RECORD_SCHEMAS) + ["events", "a_later_versions_channel"])
def test_every_record_channel_schema_is_accepted(channel):
    name, schema = json_schema_of(channel)
    types = parse_json_schema(schema, name)
    # every documented field is offered to the plot panel
    assert {f["name"] for f in types[name]} == set(schema["properties"])


def test_every_json_schema_in_a_recording_is_accepted(tmp_path):
    from sim.loop import ClosedLoop
    from sim.recorder import SimRecorder, recording_meta
    from sim.scene import load_scene, with_run_overrides

    from foveatrack.recording.writer import RecordingWriter

    root = Path(__file__).resolve().parents[2]
    scene = with_run_overrides(load_scene(root / "scenes" / "fig12-tracking.toml"), 0.3, None)
    loop = ClosedLoop(scene)
    path = tmp_path / "run.mcap"
    with RecordingWriter(path, recording_meta(scene, loop)) as w:
        loop.frame_hook = SimRecorder(w)
        loop.run()
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    json_schemas = [s for s in summary.schemas.values() if s.encoding == "jsonschema"]
    assert len(json_schemas) >= 4     # detections, head, commands, truth (metrics: the daemon)
    for s in json_schemas:
        parse_json_schema(json.loads(s.data), s.name)
