"""The Python client against real tpr-extractor and tpr-indexer processes:
add a folder (ids and labels as `tpr add` gives them), query by mesh and by
id (ranking compared with the distances the indexer reports for each pair),
get, list, stats, remove, and errors carrying the gRPC code."""

import os

import grpc
import pytest

from tpr import Client, TprError, collect_files


def classes(folder):
    return sorted(d for d in os.listdir(folder) if os.path.isdir(os.path.join(folder, d)))


def test_add_query_get_remove(services, meshes):
    extractor, indexer, _ = services
    with Client(extractor=extractor.address, indexer=indexer.address) as client:
        ids = client.add(meshes)
        expected = sorted(i for _, i, _ in collect_files(meshes))
        assert sorted(ids) == expected and len(ids) == 4
        assert client.add(meshes) == []  # present ids are skipped
        stats = client.stats()
        assert stats.models == 4
        assert dict(stats.labels) == {c: 2 for c in classes(meshes)}

        first = expected[0]
        model = client.get(first)
        assert model.label == first.split("/")[0]
        assert model.metadata["sha256"]
        assert len(model.signature.features) > 0

        by_id = client.query(first, k=4)
        assert [n.rank for n in by_id] == [1, 2, 3, 4]
        assert by_id[0].id == first and by_id[0].distance == pytest.approx(0, abs=1e-9)
        distances = [n.distance for n in by_id]
        assert distances == sorted(distances)
        # The oracle: each neighbour's distance is the one a query by that
        # neighbour reports back for `first` (the distance is symmetric).
        for n in by_id[1:]:
            back = {m.id: m.distance for m in client.query(n.id, k=4)}
            assert back[first] == pytest.approx(n.distance, rel=1e-9)

        path = [p for p, i, _ in collect_files(meshes) if i == first][0]
        by_mesh = client.query(path, k=2, intent="identity")
        assert by_mesh[0].id == first

        stream = client.search(first, k=4, label=model.label)
        assert {n.label for n in stream} == {model.label}
        assert [m.id for m in client.list()] == expected

        client.remove(first)
        with pytest.raises(TprError) as e:
            client.get(first)
        assert e.value.code == grpc.StatusCode.NOT_FOUND


def test_labels_and_errors(services, meshes):
    extractor, indexer, _ = services
    with Client(extractor=extractor.address, indexer=indexer.address) as client:
        sub = os.path.join(meshes, classes(meshes)[0])
        ids = client.add(sub, label="mine")
        assert all(client.get(i).label == "mine" for i in ids)
        with pytest.raises(TprError) as e:
            client.query("no-such-id")
        assert e.value.code == grpc.StatusCode.NOT_FOUND
        with pytest.raises(TprError) as e:
            client.query(ids[0], intent="fast")
        assert e.value.code == grpc.StatusCode.INVALID_ARGUMENT

    # The extractor given as the indexer, and a service that is down.
    with Client(extractor=extractor.address, indexer=extractor.address, timeout=5) as wrong:
        with pytest.raises(TprError) as e:
            wrong.stats()
        assert e.value.code == grpc.StatusCode.UNIMPLEMENTED
        assert "not a tpr-indexer" in e.value.message
    extractor.stop()
    with Client(extractor=extractor.address, indexer=indexer.address, timeout=5) as down:
        with pytest.raises(TprError) as e:
            down.add(sub)
        assert e.value.code == grpc.StatusCode.UNAVAILABLE
        assert f"cannot reach tpr-extractor at {extractor.address}" in e.value.message
