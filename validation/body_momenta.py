"""The momentum of each body at the first and last output times of a run, from the cells of its
solution.xdmf: rho |c| v_c summed over the cells of each `body` (one material of density rho).

    PYVISTA_OFF_SCREEN=true .venv/bin/python validation/body_momenta.py results/two-balls --rho 100
"""

import argparse
import json
import pathlib

import numpy as np
import pyvista as pv


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=pathlib.Path)
    parser.add_argument("--rho", type=float, required=True, help="the density (kg/m^3)")
    args = parser.parse_args()
    reader = pv.XdmfReader(str(args.run / "solution.xdmf"))
    out = {}
    for t in (reader.time_values[0], reader.time_values[-1]):
        reader.set_active_time_value(t)
        blocks = reader.read()  # one grid per function, the same cells
        cells = {name: blocks[k].cell_data[name] for k in range(blocks.n_blocks)
                 for name in blocks[k].cell_data.keys()}
        volume = blocks[0].compute_cell_sizes(length=False, area=False, volume=True).cell_data["Volume"]
        body, v = cells["body"], cells["velocity"]
        out[f"{t:.6g}"] = {int(b): (args.rho * volume[body == b, None] * v[body == b]).sum(axis=0).tolist()
                          for b in np.unique(body)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
