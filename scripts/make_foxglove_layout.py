"""Write docs/foxglove-layout.json: the Foxglove layout for a foveatrack recording or live view,
built with the Foxglove SDK's layout types (``foxglove.layouts``).

    python scripts/make_foxglove_layout.py [OUT.json]

Left: the 3D view in the world frame (the cloud on /points with its per-point reflectivity, the
scene entities on /scene, the frames head_est, head_true and lidar from /tf).  Right, top to bottom:
the tracking error per axis (what the controller saw, with the dead band's meaning: each axis on
its own), the head angles (the tracker's dead-reckoned estimate and, in simulation, the truth), the
multi-object tracker's tracks of the frame as a table (``/tracks``: recordings of a ``[tracker.sky]``
run; empty otherwise), and the log (tracker state changes, the gate's interventions, daemon events).
"""

from __future__ import annotations

from pathlib import Path

import foxglove.layouts as fl

ROOT = Path(__file__).resolve().parents[1]


def layout() -> fl.Layout:
    three_d = fl.ThreeDeePanel(title="world: cloud, D, detection, trajectories", config=fl.ThreeDeeConfig(
        follow_tf="world", follow_mode="follow-none",
        topics={"/points": fl.BaseRendererPointCloudTopicSettings(visible=True, point_size=3, color_mode="colormap",
                                                                  color_field="reflectivity", color_map="turbo"),
                "/scene": fl.BaseRendererSceneUpdateTopicSettings(visible=True),
                # D and the trajectories' histories, re-sent once a second (what a seek restores)
                "/scene_keyframe": fl.BaseRendererSceneUpdateTopicSettings(visible=True)}))
    error = fl.PlotPanel(title="controller's error per axis [deg]", config=fl.PlotConfig(
        show_legend=True, y_axis_label="deg", paths=[
            fl.PlotSeries(value="/detections.error_pan_deg", label="pan error (detection)"),
            fl.PlotSeries(value="/detections.error_tilt_deg", label="tilt error (detection)"),
            fl.PlotSeries(value="/truth.true_error_deg", label="true off-axis angle (simulation)",
                          line_style="dashed")]))
    head = fl.PlotPanel(title="head angles [deg]", config=fl.PlotConfig(
        show_legend=True, y_axis_label="deg", paths=[
            fl.PlotSeries(value="/head.pan_deg", label="pan, dead-reckoned"),
            fl.PlotSeries(value="/head.tilt_deg", label="tilt, dead-reckoned"),
            fl.PlotSeries(value="/truth.pan_deg", label="pan, true (simulation)", line_style="dashed"),
            fl.PlotSeries(value="/truth.tilt_deg", label="tilt, true (simulation)", line_style="dashed")]))
    log = fl.LogPanel(title="events", config=fl.LogConfig(topic_to_render="/log", show_name=True))
    # the multi-object tracker's tracks of the frame, one row each (recordings of a [tracker.sky] run)
    tracks = fl.TablePanel(title="tracks ([tracker.sky] runs)", config=fl.TableConfig(topic_path="/tracks.tracks"))
    right = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=1, content=error), fl.SplitItem(proportion=1, content=head),
        fl.SplitItem(proportion=0.6, content=tracks), fl.SplitItem(proportion=0.6, content=log)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=1.4, content=three_d), fl.SplitItem(proportion=1, content=right)]))


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description="write the Foxglove layout for recordings and the live view")
    ap.add_argument("out", nargs="?", type=Path, default=ROOT / "docs" / "foxglove-layout.json",
                    help="where to write it (default: docs/foxglove-layout.json)")
    out = ap.parse_args().out     # (a bare sys.argv[1] once wrote the layout to a file named '--help')
    import json

    out.write_text(json.dumps(json.loads(layout().to_json()), indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
