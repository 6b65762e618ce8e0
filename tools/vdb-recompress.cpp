// Rewrites a .vdb file with other compression settings, with OpenVDB itself, so the tests can
// read zip-compressed and uncompressed files as OpenVDB writes them (its Python module writes
// only its default, blosc). Needs libopenvdb-dev (Debian). Used by make-vdb-test-data.py:
//
//     g++ -O1 -std=c++17 tools/vdb-recompress.cpp -o /tmp/vdb-recompress -lopenvdb -ltbb
//     /tmp/vdb-recompress IN.vdb FLAGS OUT.vdb
//
// FLAGS is OpenVDB's compression bit set: 0 none, 1 zip, 2 active mask, 4 blosc.
#include <openvdb/openvdb.h>

#include <cstdlib>
#include <iostream>

int main(int argc, char** argv) {
    if (argc != 4) {
        std::cerr << "usage: vdb-recompress IN.vdb FLAGS OUT.vdb\n";
        return 2;
    }
    openvdb::initialize();
    openvdb::io::File in(argv[1]);
    in.open();
    openvdb::GridPtrVecPtr grids = in.getGrids();
    in.close();
    openvdb::io::File out(argv[3]);
    out.setCompression(static_cast<uint32_t>(std::atoi(argv[2])));
    out.write(*grids);
    out.close();
    return 0;
}
