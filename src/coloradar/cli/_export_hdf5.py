"""``coloradar export RUN OUT.h5 --format hdf5``: the options and the runner of the HDF5 branch
of ``export`` (kept apart from the ROS bag options)."""

from __future__ import annotations

import argparse

from ..progress import Progress
from ._common import did_you_mean, positive_float, positive_int

HDF5 = "hdf5"


def _products(text: str) -> tuple[str, ...]:
    """``--products``: comma-separated names of :data:`coloradar.learning.samples.PRODUCTS`
    (checked by the parser, so that a misspelt one is a usage error before any work)."""
    from ..learning.samples import PRODUCTS

    prods = tuple(p.strip() for p in text.split(",") if p.strip())
    for p in prods or ("",):
        if p not in PRODUCTS:
            raise argparse.ArgumentTypeError(f"unknown product {p!r}; {did_you_mean(p, PRODUCTS)}"
                                             f"(products: {', '.join(PRODUCTS)})")
    return prods


def add_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("hdf5 (learning data; needs h5py: pip install 'coloradar[hdf5]')")
    g.add_argument("--radar", choices=("cascade", "single_chip"), default="cascade",
                   help="radar whose frames are the samples (default cascade)")
    g.add_argument("--products", type=_products, default=("heatmap", "bev"),
                   help="comma-separated radar products: heatmap, points, polar, bev "
                        "(default heatmap,bev)")
    g.add_argument("--lidar-scans", action="store_true",
                   help="also store the nearest raw lidar scan of every sample (1 MiB each)")
    g.add_argument("--no-targets", action="store_true",
                   help="no lidar targets (the lidar map cut to each radar frame's view)")
    g.add_argument("--cell", type=positive_float, default=0.1, help="BEV cell in m (default 0.1)")
    g.add_argument("--reduce", choices=("max", "mean"), default="max",
                   help="elevation reduction of the images (default max)")
    g.add_argument("--voxel-size", type=positive_float, default=0.1,
                   help="lidar map voxel in m (default 0.1)")
    g.add_argument("--min-hits", type=positive_int, default=1,
                   help="lidar scans that must hit a map voxel (default 1)")
    g.add_argument("--compression", choices=("gzip", "lzf", "none"), default="gzip",
                   help="dataset compression (default gzip, level 1 with byte shuffle: every "
                        "HDF5 reader has it)")


def run(args: argparse.Namespace) -> int:
    from ..dataset import open_sequence
    from ..interop.hdf5 import export_hdf5
    from ..learning import BevGrid, TargetSettings, ViewOptions

    products = args.products
    seq = open_sequence(args.run, calib=args.calib)
    grid = BevGrid.for_radar(seq.radar(args.radar).heatmap_config, cell=args.cell)
    prog = Progress(0, f"{seq.name} -> hdf5", unit="frames", enabled=not args.quiet)
    res = export_hdf5(seq, args.out, radar=args.radar, products=products,
                      lidar=args.lidar_scans, targets=not args.no_targets,
                      target_settings=TargetSettings(voxel_size=args.voxel_size,
                                                     min_hits=args.min_hits),
                      views=ViewOptions(grid=grid, reduce=args.reduce),
                      compression=args.compression, overwrite=args.overwrite, progress=prog)
    prog.close()
    sec = max(res.seconds, 1e-9)
    print(f"{res.path}: hdf5, {res.frames} {args.radar} frames in {res.seconds:.1f} s "
          f"({res.frames / sec:.1f} frames/s), {res.bytes / 2**20:.1f} MiB "
          f"({res.bytes / max(res.frames, 1) / 2**10:.0f} KiB/frame)")
    for key, shape in res.shapes.items():
        print(f"  {key:<16} {' x '.join(map(str, shape))}")
    for why, n in res.dropped.items():
        print(f"  left out {n} frames: {why}")
    return 0
