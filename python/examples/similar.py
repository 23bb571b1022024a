#!/usr/bin/python3
"""Index a folder of meshes and list the models most like one of them.

    scripts/demo                                  # starts the services
    PYTHONPATH=build/python /usr/bin/python3 python/examples/similar.py \
        /work/shared/data/sample dog.off

Distances run from 0 (the same shape) to about 0.4; below about 0.05 is
the same model in another pose (docs/distances.md).
"""

import sys

from tpr import Client, TprError


def main(folder: str, mesh: str) -> int:
    with Client(extractor="127.0.0.1:7001", indexer="127.0.0.1:7002") as client:
        try:
            added = client.add(folder)
            print(f"{len(added)} models added; {client.stats().models} indexed")
            for n in client.query(mesh, k=5, intent="kind"):
                print(f"{n.rank:2d}  {n.id:40s} {n.label:16s} {n.distance:.4f}")
        except TprError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: similar.py FOLDER MESH")
    sys.exit(main(sys.argv[1], sys.argv[2]))
