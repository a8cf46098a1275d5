"""A tall bottle's pick on a generated LIBERO scene is confirmed by the verifier (issue 28).

LIBERO's bottles and cartons (tasks 2, 3, 4, 7, 9 of libero_object) were never confirmed:
the part of the bottle below the fingers was taken for the bottle standing on the table,
which vetoed the holding relation, and the held-object model has no wrist load on
robosuite's Panda. The scene is generated (LIBERO's placement sampler, ``generated: true``),
never an evaluation init state; the looks are the ones the bench measures on generated
scenes (``phyagentos.targets.libero.descriptors``).
"""

from __future__ import annotations


import pytest
import yaml
from libero_generated_pick import run_generated_pick


pytestmark = pytest.mark.sim

# looks measured on generated cluttered scenes (the bench's libero/descriptors.yaml, generated_clutter_v2)
LOOKS = {
    "salad_dressing": {"colour": [0.09, 0.094, 0.082], "size_m": [0.0375, 0.0375, 0.1461], "shape": "cylinder"},
    "basket": {"colour": [0.534, 0.512, 0.445], "size_m": [0.1747, 0.1641, 0.1407]},
    "ketchup": {"colour": [0.318, 0.112, 0.01], "size_m": [0.0377, 0.0372, 0.1464]},
    "alphabet_soup": {"colour": [0.182, 0.184, 0.258], "size_m": [0.0682, 0.0682, 0.0796], "shape": "cylinder"},
    "cream_cheese": {"colour": [0.284, 0.32, 0.471], "size_m": [0.0851, 0.0459, 0.0195], "shape": "box"},
    "milk": {"colour": [0.412, 0.143, 0.088], "size_m": [0.0536, 0.0413, 0.1365]},
    "tomato_sauce": {"colour": [0.224, 0.122, 0.055], "size_m": [0.0678, 0.0678, 0.0796], "shape": "cylinder"},
}


def test_a_tall_bottles_pick_on_a_generated_scene_is_confirmed_and_it_is_really_held(tmp_path):
    rep = run_generated_pick(tmp_path, name="tall_pick", description="pick up the salad dressing", suite="libero_object", task=2,
                             looks=LOOKS, fixture={"name": "floor", "class": "floor"}, obj="salad_dressing_1")
    first = rep["sessions"][0]
    assert first["verdict"] == "success", first["reason"]
    assert rep["succeeded"]
    # what really happened (the privileged record, read by this test only): the bottle is in the hand, risen
    truth = yaml.safe_load((tmp_path / "ws" / first["evidence"] / "ground_truth.yaml").read_text())
    assert truth["scene_record"]["init_state"] is None and truth["scene_record"]["generated"] is True
    assert truth["terminal"]["held"] == ["salad_dressing_1"]
    z0 = truth["initial"]["objects"]["salad_dressing_1"]["position"][2]
    assert truth["terminal"]["objects"]["salad_dressing_1"]["position"][2] - z0 > 0.1
