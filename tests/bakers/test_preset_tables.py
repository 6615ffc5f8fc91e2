"""The spec's preset tables state the numbers the code uses (bakers/presets.py, nasset_sdk.kinds.*.SIZES).

Each table row is read as the integers it contains, in order ("16 384" is one number, "64²" is 64), and
compared with the same numbers taken from the code. A preset changed in one place and not the other fails.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from nasset_bakers import presets
from nasset_sdk.kinds import eightdna, neupress, rna

SPEC = Path(__file__).resolve().parents[2] / "spec"
NUMBER = re.compile(r"\d+(?: \d{3})*")


def table_rows(doc: str, header: str) -> dict[str, list[int]]:
    """The rows of the table whose header line starts with ``header``: first cell's first word -> integers of the other cells."""
    lines = (SPEC / doc).read_text(encoding="utf-8").splitlines()
    start = next((i for i, line in enumerate(lines) if line.startswith(header)), None)
    assert start is not None, f"{doc}: no table headed {header!r}"
    rows = {}
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0].split()[0]] = [int(n.replace(" ", "")) for n in NUMBER.findall(" | ".join(cells[1:]))]
    return rows


def flat(values) -> list[int]:
    out = []
    for v in values:
        out.extend(flat(v) if isinstance(v, tuple | list) else [v])
    return out


def test_neupress_data_table():
    rows = table_rows("bake-neupress.md", "| preset | views | res | spp |")
    for size, d in presets.NEUPRESS_MITSUBA_DATA.items():
        assert rows[size] == [d["views"], d["res"], d["spp"], d["val_views"], d["val_res"], d["val_spp"]], size


def test_blender_data_table():
    rows = table_rows("bake-blender.md", "| preset | train views")
    for size, d in presets.RNA_BLENDER_DATA.items():
        r, c, layers, width = rna.SIZES[size]
        suns = lambda s: [s["lights_per_view"]] if s.get("lights_per_view", 1) != 1 else []  # noqa: E731 ("8 suns"; one: not written)
        expect = [d["views"], d["res"], d["spp"], *suns(d)]
        if size in presets.RNA_BLENDER_FIBER_DATA:
            fd = {**d, **presets.RNA_BLENDER_FIBER_DATA[size]}
            expect += [fd["views"], fd["res"], fd["spp"], *suns(fd)]
        epochs = presets.RNA_BLENDER_TRAIN.get(size, {}).get("epochs")
        expect += [d["val_views"], d["val_res"], d["val_spp"], layers, width, *([epochs] if epochs else [])]  # "24 epochs"
        if size in presets.RNA_BLENDER_FIBER_TRAIN:
            expect += [layers, presets.RNA_BLENDER_FIBER_TRAIN[size]["hidden"]]
        assert rows[size] == expect + [r, c], size


def test_eightdna_bake_table():
    rows = table_rows("bake-8dna.md", "| preset | steps × batch")
    for size, t in presets.EIGHTDNA_TRAIN.items():
        model = [] if size == "hq" else flat(eightdna.SIZES[size])  # hq: "the paper's sizes" (kinds/8dna.md)
        heldout = presets.EIGHTDNA_MITSUBA_SAMPLER[size]["heldout"]
        assert rows[size] == [t["steps"], t["batch"], t["buffer"], t["reuse"], *model, heldout], size
    text = (SPEC / "bake-8dna.md").read_text(encoding="utf-8")  # the weight average, in the training paragraph
    averaged = [size for size, t in presets.EIGHTDNA_TRAIN.items() if t.get("average")]
    assert averaged == ["small"] and "`small` exports an exponential average of the weights" in text
    assert f"(`average` {presets.EIGHTDNA_TRAIN['small']['average']}:" in text


@pytest.mark.parametrize("doc, header, sizes", [
    ("kinds/rna.md", "| preset | R | C |", rna.SIZES),
    ("kinds/neupress.md", "| preset | M |", neupress.SIZES),
    ("kinds/8dna.md", "| preset | R | C | Q |", eightdna.SIZES),
])
def test_network_size_tables(doc, header, sizes):
    rows = table_rows(doc, header)
    assert set(rows) == set(sizes)
    for size, shape in sizes.items():
        assert rows[size] == flat(shape), (doc, size)
