import io
import struct

import laspy
import numpy as np
import pytest
from pyproj import CRS, Transformer

from gisroads.io.las import (LasError, LasPointWriter, iter_las_chunks, las_info, read_las,
                             write_classified)

EXPECTED = {  # file: (point count, EPSG or None, horizontal unit)
    "fusa.laz": (277573, 32754, "metre"),
    "zurich.laz": (656837, None, "unknown (assumed metre)"),
    "crop_1.laz": (210582, 2154, "metre"),
    "test_semis_2023_0292_6833_LA93_IGN69.laz": (289055, 2154, "metre"),
    "autzen_trim.laz": (110000, None, "foot"),
    "Megaplot.laz": (81590, 26917, "metre"),
    "las_with_several_extra_byte_bloc.laz": (697721, 2154, "metre"),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_info_reads_every_real_file(lidar_dir, name):
    count, epsg, unit = EXPECTED[name]
    info = las_info(lidar_dir / name)
    assert info["point_count"] == count
    assert info["epsg"] == epsg
    assert info["horizontal_unit"] == unit
    assert info["format"] == "LAZ"


def test_autzen_feet_are_converted_to_metres_consistently(lidar_dir):
    path = lidar_dir / "autzen_trim.laz"
    info = las_info(path)
    assert info["unit_to_metre"] == pytest.approx(0.3048)
    assert "Lambert" in info["crs"]
    cloud = read_las(path)
    with laspy.open(path) as r:
        raw = r.read()
    np.testing.assert_allclose(cloud.xyz[:, 0], np.asarray(raw.x) * 0.3048)
    np.testing.assert_allclose(cloud.xyz[:, 2], np.asarray(raw.z) * 0.3048)
    # The metre working CRS is the file's projection with metre axes: going back to the
    # file's CRS must give the file's own (foot) coordinates.
    back = Transformer.from_crs(cloud.crs, cloud.source_crs, always_xy=True)
    x, y = back.transform(cloud.xyz[:100, 0], cloud.xyz[:100, 1])
    np.testing.assert_allclose(x, np.asarray(raw.x[:100]), atol=1e-4)
    np.testing.assert_allclose(y, np.asarray(raw.y[:100]), atol=1e-4)
    assert cloud.crs.axis_info[0].unit_name == "metre"


def test_chunked_reading_equals_whole_and_bbox_filters(lidar_dir):
    path = lidar_dir / "fusa.laz"
    whole = read_las(path)
    chunks = list(iter_las_chunks(path, chunk_size=50_000))
    assert len(chunks) == 6 and sum(len(c) for c in chunks) == len(whole) == 277573
    np.testing.assert_array_equal(np.concatenate([c.xyz for c in chunks]), whole.xyz)
    assert whole.crs.to_epsg() == 32754
    assert whole.intensity is not None and whole.intensity.max() > 0
    bbox = (277800.0, 6122300.0, 277850.0, 6122350.0)
    part = read_las(path, bbox=bbox, chunk_size=100_000)
    inside = ((whole.xyz[:, 0] >= bbox[0]) & (whole.xyz[:, 0] <= bbox[2])
              & (whole.xyz[:, 1] >= bbox[1]) & (whole.xyz[:, 1] <= bbox[3]))
    assert len(part) == inside.sum() > 5000


@pytest.mark.parametrize("name", ["fusa.laz", "test_semis_2023_0292_6833_LA93_IGN69.laz",
                                  "las_with_several_extra_byte_bloc.laz"])
def test_kept_fields_decode_as_in_the_file_and_ranges_join_into_it(lidar_dir, name):
    # point formats 1, 6 (with GPS time, scan angle...) and 8 (colours, extra bytes): only
    # the layers a cloud keeps are decoded
    path = lidar_dir / name
    raw = laspy.read(path)
    whole = read_las(path)
    for field in ("classification", "return_number", "number_of_returns", "intensity"):
        np.testing.assert_array_equal(getattr(whole, field), np.asarray(raw[field]))
    np.testing.assert_allclose(whole.xyz, np.column_stack([raw.x, raw.y, raw.z]))
    # ranges of the file, decoded from inside its compressed chunks, join into the whole
    cuts = [0, 12_345, 100_000, 100_001, len(whole)]
    parts = [c.xyz for a, b in zip(cuts, cuts[1:])
             for c in iter_las_chunks(path, start=a, stop=b, chunk_size=30_000)]
    assert [len(p) for p in parts[:2]] == [12_345, 30_000]
    np.testing.assert_array_equal(np.concatenate(parts), whole.xyz)


POINT_FORMATS = [("1.2", pf) for pf in range(4)] + [("1.3", pf) for pf in range(6)] + \
    [("1.4", pf) for pf in range(11)]


@pytest.mark.parametrize("suffix", ["las", "laz"])
@pytest.mark.parametrize("version,point_format", POINT_FORMATS)
def test_every_version_and_point_format(tmp_path, version, point_format, suffix):
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = [0.01, 0.01, 0.01]
    las = laspy.LasData(header)
    rng = np.random.default_rng(point_format)
    las.x, las.y, las.z = rng.uniform(0, 100, (3, 500))
    las.intensity = rng.integers(0, 4000, 500)
    las.classification = np.full(500, 2)
    path = tmp_path / f"pf{point_format}.{suffix}"
    las.write(path)
    assert las_info(path)["format"] == suffix.upper()
    cloud = read_las(path)
    np.testing.assert_allclose(cloud.xyz[:, 0], las.x, atol=0.005)
    np.testing.assert_array_equal(cloud.intensity, las.intensity)
    assert (cloud.classification == 2).all()


def test_las_1_0(tmp_path):
    # laspy writes no 1.0 files; a 1.2 header with point format 1 has the 1.0 layout, so
    # setting its minor version byte (offset 25) and zeroing the global-encoding field that
    # 1.0 reserves (offset 6-7) gives a genuine LAS 1.0 file.
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.x, las.y, las.z = np.arange(5.0), np.arange(5.0) * 2, np.ones(5)
    las.intensity = np.arange(5) + 100
    las.write(tmp_path / "v12.las")
    data = bytearray((tmp_path / "v12.las").read_bytes())
    data[6:8] = b"\0\0"
    data[25] = 0
    (tmp_path / "v10.las").write_bytes(bytes(data))
    assert las_info(tmp_path / "v10.las")["version"] == "1.0"
    cloud = read_las(tmp_path / "v10.las")
    np.testing.assert_allclose(cloud.xyz[:, 1], np.arange(5.0) * 2)
    assert cloud.intensity.tolist() == [100, 101, 102, 103, 104]


def pointwise_laz(chunked: bytes, chunk_size: int = 50_000) -> bytes:
    """A LAZ file of LASzip's first, pointwise compressor, from a one-chunk LAZ file.

    In both layouts a chunk is the first point raw and then the arithmetic-coded rest; the
    pointwise file is that stream alone, right at the point-data offset, where the chunked
    file puts the 8-byte offset of its chunk table before the points and the table after
    them. The LASzip VLR (after its 54-byte VLR header) starts with the compressor code;
    its chunk-size field (byte 12) means nothing to a pointwise file: the first LASzip
    releases left it 0, later ones 50000.
    """
    header = laspy.LasHeader.read_from(io.BytesIO(chunked))
    start = header.offset_to_point_data
    (chunk_table,) = struct.unpack_from("<q", chunked, start)
    data = bytearray(chunked[:start] + chunked[start + 8:chunk_table])
    laszip_record = chunked.index(b"laszip encoded") - 2 + 54
    assert struct.unpack_from("<H", data, laszip_record) == (2,)  # pointwise chunked
    struct.pack_into("<H", data, laszip_record, 1)
    struct.pack_into("<I", data, laszip_record + 12, chunk_size)
    return bytes(data)


def as_version_1_0_or_1_1(data: bytes, minor: int) -> bytes:
    """A LAS 1.2 file with point format 0 or 1 relabelled 1.0 or 1.1 (the same layout): the
    minor version byte (offset 25) set and the global encoding that 1.0 reserves zeroed."""
    data = bytearray(data)
    data[6:8] = b"\0\0"
    data[25] = minor
    return bytes(data)


@pytest.mark.parametrize("version,point_format,chunk_size", [
    ("1.0", 1, 0), ("1.1", 0, 0), ("1.2", 0, 50_000), ("1.2", 1, 0), ("1.2", 2, 50_000),
    ("1.2", 3, 50_000)])
def test_pointwise_laz_reads_the_points_of_its_las(tmp_path, version, point_format,
                                                   chunk_size):
    las = laspy.LasData(laspy.LasHeader(point_format=point_format, version="1.2"))
    las.header.scales, las.header.offsets = [0.01] * 3, [500000.0, 4500000.0, 0.0]
    rng = np.random.default_rng(point_format)
    las.x = 500000 + rng.uniform(0, 100, 3000)
    las.y = 4500000 + rng.uniform(0, 60, 3000)
    las.z = rng.uniform(0, 5, 3000)
    las.intensity = rng.integers(0, 4000, 3000)
    las.classification = rng.integers(1, 3, 3000)
    las.write(tmp_path / "source.las")
    las.write(tmp_path / "chunked.laz")
    data = pointwise_laz((tmp_path / "chunked.laz").read_bytes(), chunk_size)
    if version != "1.2":
        data = as_version_1_0_or_1_1(data, int(version[-1]))
    path = tmp_path / "pointwise.laz"
    path.write_bytes(data)
    # the 8 bytes after the point-data offset are now coordinates of the first point
    start = laspy.LasHeader.read_from(io.BytesIO(data)).offset_to_point_data
    assert not start < struct.unpack_from("<q", data, start)[0] < len(data)

    info = las_info(path)
    assert (info["format"], info["version"], info["point_count"]) == ("LAZ", version, 3000)
    expected = read_las(tmp_path / "source.las")
    cloud = read_las(path)
    np.testing.assert_array_equal(cloud.xyz, expected.xyz)
    np.testing.assert_array_equal(cloud.intensity, expected.intensity)
    np.testing.assert_array_equal(cloud.classification, expected.classification)
    chunks = list(iter_las_chunks(path, chunk_size=700))
    assert [len(c) for c in chunks] == [700] * 4 + [200]
    np.testing.assert_array_equal(np.concatenate([c.xyz for c in chunks]), expected.xyz)
    changed = write_classified(path, tmp_path / "tagged.laz",
                               lambda c: np.where(c.xyz[:, 0] < 500050, 11, c.classification))
    assert changed == np.count_nonzero(expected.xyz[:, 0] < 500050)
    np.testing.assert_array_equal(read_las(tmp_path / "tagged.laz").xyz, expected.xyz)


def test_truncated_pointwise_laz_is_refused_when_decoded(tmp_path):
    las = laspy.LasData(laspy.LasHeader(point_format=1, version="1.2"))
    las.x, las.y, las.z = np.random.default_rng(0).uniform(0, 100, (3, 3000))
    las.write(tmp_path / "chunked.laz")
    data = pointwise_laz((tmp_path / "chunked.laz").read_bytes())
    (tmp_path / "cut.laz").write_bytes(data[:len(data) // 2])
    with pytest.raises(LasError, match="corrupt point data"):
        read_las(tmp_path / "cut.laz")
    # cut inside its first, raw point: nothing to decode, refused from the header
    start = laspy.LasHeader.read_from(io.BytesIO(data)).offset_to_point_data
    (tmp_path / "cut.laz").write_bytes(data[:start + 10])
    with pytest.raises(LasError, match="truncated LAZ file"):
        las_info(tmp_path / "cut.laz")


def test_file_without_intensity_reports_none(tmp_path):
    header = laspy.LasHeader(point_format=0, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = np.arange(10.0), np.arange(10.0), np.zeros(10)
    las.write(tmp_path / "noi.las")
    assert read_las(tmp_path / "noi.las").intensity is None


@pytest.mark.parametrize("cut", [0.5, 0.95])
def test_truncated_laz_is_refused_from_the_header(lidar_dir, tmp_path, cut):
    data = (lidar_dir / "fusa.laz").read_bytes()
    bad = tmp_path / "cut.laz"
    bad.write_bytes(data[:int(len(data) * cut)])
    with pytest.raises(LasError, match="truncated"):
        las_info(bad)
    with pytest.raises(LasError, match="truncated"):
        read_las(bad)


def test_truncated_las_is_refused(tmp_path):
    header = laspy.LasHeader(point_format=1, version="1.2")
    las = laspy.LasData(header)
    las.x = las.y = las.z = np.arange(1000.0)
    las.write(tmp_path / "a.las")
    data = (tmp_path / "a.las").read_bytes()
    (tmp_path / "b.las").write_bytes(data[:-100])
    with pytest.raises(LasError, match="truncated"):
        read_las(tmp_path / "b.las")


def test_empty_and_garbage_files(tmp_path):
    header = laspy.LasHeader(point_format=6, version="1.4")
    with laspy.open(tmp_path / "empty.laz", mode="w", header=header, do_compress=True):
        pass
    with pytest.raises(LasError, match="no points"):
        las_info(tmp_path / "empty.laz")
    (tmp_path / "zero.laz").write_bytes(b"")
    (tmp_path / "junk.las").write_bytes(b"not a lidar file" * 100)
    for name in ("zero.laz", "junk.las", "missing.laz"):
        with pytest.raises(LasError):
            las_info(tmp_path / name)


def test_writer_round_trip_with_crs(tmp_path):
    rng = np.random.default_rng(0)
    xyz = rng.uniform([500000, 4500000, 100], [500100, 4500100, 120], (20000, 3))
    path = tmp_path / "w.laz"
    with LasPointWriter(path, crs=CRS("EPSG:32633"), offset=(500000, 4500000, 0)) as w:
        for part in np.array_split(np.arange(len(xyz)), 3):
            w.write(xyz[part], intensity=np.full(len(part), 7),
                    classification=np.full(len(part), 2))
    cloud = read_las(path)
    assert len(cloud) == 20000 and cloud.crs.to_epsg() == 32633
    np.testing.assert_allclose(cloud.xyz, xyz, atol=0.0006)
    assert (cloud.intensity == 7).all()


def test_writer_leaves_nothing_on_failure(tmp_path):
    path = tmp_path / "w.laz"
    with pytest.raises(RuntimeError):
        with LasPointWriter(path, crs=None) as w:
            w.write(np.zeros((10, 3)))
            raise RuntimeError("cancelled")
    assert list(tmp_path.iterdir()) == []


def test_write_classified_changes_only_classes(lidar_dir, tmp_path):
    source = lidar_dir / "fusa.laz"
    target = tmp_path / "tagged.laz"
    changed = write_classified(source, target,
                               lambda c: np.where(c.xyz[:, 0] < 277800, 11, c.classification),
                               chunk_size=100_000)
    before, after = read_las(source), read_las(target)
    west = before.xyz[:, 0] < 277800
    assert changed == np.count_nonzero(west & (before.classification != 11)) > 0
    assert (after.classification[west] == 11).all()
    np.testing.assert_array_equal(after.classification[~west], before.classification[~west])
    np.testing.assert_array_equal(after.xyz, before.xyz)
    np.testing.assert_array_equal(after.intensity, before.intensity)
    assert after.crs == before.crs


def test_write_classified_is_atomic(lidar_dir, tmp_path):
    target = tmp_path / "tagged.laz"
    target.write_bytes(b"previous")
    with pytest.raises(ValueError, match="classes"):
        write_classified(lidar_dir / "fusa.laz", target, lambda c: np.zeros(3))
    assert target.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["tagged.laz"]
