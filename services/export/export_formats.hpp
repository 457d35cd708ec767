// The formats of `bsn export`, one writer each: CSV per topic (export_csv.cpp), OpenSim orientation and motion files
// (export_opensim.cpp), BROAD HDF5 per node (export_broad.cpp). Each returns the number of files it wrote and throws
// io::IoError naming the file it cannot read or write.
#pragma once

#include <filesystem>

#include "bsn/io/session_file.hpp"
#include "export_service.hpp"

namespace bsn::services {

/// One CSV file per topic, joint angles one per joint.
int export_csv(const io::SessionReader& r, const std::filesystem::path& out);
/// OpenSense orientation files (.sto) of the estimates and the truth, and motion files (.mot) of the joint angles.
int export_sto(const io::SessionReader& r, const std::filesystem::path& out, const ExportOptions& opt);
/// One BROAD-layout HDF5 file per node of bsn/raw, with the truth as the reference where it was recorded.
int export_broad(const io::SessionReader& r, const std::filesystem::path& out);

}  // namespace bsn::services
