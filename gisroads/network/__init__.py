"""The road-network floor shared by every method: evidence in, a clean connected network out.

Below the methods and above the vectorisers, so no method imports another:

:mod:`gisroads.network.subgraph`
    Gap edges between road-part ends, their weights, and the integer program that keeps one
    link per end (Grote & Rottensteiner 2010, Sec. 2.2), chaining parts into road strings.
:mod:`gisroads.network.junctions`
    Road strings to a network: approximation, duplicates, junction construction and
    significance (Sec. 2.3).
:mod:`gisroads.network.cuts`
    Cuts across roads closed in a road mask before its skeleton: two road ends of the same
    width facing each other across open ground.
:mod:`gisroads.network.rasters`
    Any road raster (a mask or a probability map) to road parts and, through the two stages
    above, to the network contract.
"""
