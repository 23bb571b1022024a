"""TPR Search from Python: index 3D meshes and find similar ones.

    from tpr import Client
    with Client(extractor="127.0.0.1:7001", indexer="127.0.0.1:7002") as c:
        c.add("library/")                      # ids dog1/T305.obj, ...
        for n in c.query("dog.off", k=5):
            print(n.rank, n.id, n.label, n.distance)

The messages are the generated ``tpr.v1`` protobuf modules (``tpr.v1.
indexer_pb2`` and friends); errors are :class:`TprError`, carrying the gRPC
status code.
"""

from tpr.client import Client, Neighbor, TprError, collect_files

__all__ = ["Client", "Neighbor", "TprError", "collect_files"]
