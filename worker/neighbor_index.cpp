#include "worker/neighbor_index.h"

#include <flann/flann.hpp>
#include <stdexcept>

namespace prt {

struct NeighborIndex::Impl {
  std::vector<float> coords;
  std::vector<uint32_t> ids;
  std::unique_ptr<flann::Index<flann::L2_Simple<float>>> index;
};

NeighborIndex::NeighborIndex(std::span<const Vec3> points, std::span<const uint32_t> ids)
    : impl_(std::make_unique<Impl>()) {
  if (points.size() != ids.size())
    throw std::invalid_argument("NeighborIndex: points/ids size mismatch");
  impl_->ids.assign(ids.begin(), ids.end());
  impl_->coords.reserve(points.size() * 3);
  for (const Vec3& p : points) {
    impl_->coords.push_back(static_cast<float>(p.x));
    impl_->coords.push_back(static_cast<float>(p.y));
    impl_->coords.push_back(static_cast<float>(p.z));
  }
  if (!points.empty()) {
    flann::Matrix<float> data(impl_->coords.data(), points.size(), 3);
    impl_->index = std::make_unique<flann::Index<flann::L2_Simple<float>>>(
        data, flann::KDTreeSingleIndexParams(12));
    impl_->index->buildIndex();
  }
}

NeighborIndex::~NeighborIndex() = default;

std::size_t NeighborIndex::size() const {
  return impl_->ids.size();
}

std::vector<uint32_t> NeighborIndex::RadiusSearch(const Vec3& query, double radius,
                                                  int max_k) const {
  std::vector<uint32_t> out;
  if (!impl_->index || max_k <= 0 || !(radius > 0)) return out;
  float q[3] = {static_cast<float>(query.x), static_cast<float>(query.y),
                static_cast<float>(query.z)};
  flann::Matrix<float> qm(q, 1, 3);
  std::vector<std::vector<size_t>> idx;
  std::vector<std::vector<float>> dist;
  flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
  params.sorted = true;
  params.max_neighbors = max_k;
  // FLANN's L2 distances are squared: the radius is given as r².
  impl_->index->radiusSearch(qm, idx, dist, static_cast<float>(radius * radius), params);
  out.reserve(idx[0].size());
  for (size_t i : idx[0]) out.push_back(impl_->ids[i]);
  return out;
}

std::vector<uint32_t> NeighborIndex::Nearest(const Vec3& query, int max_k) const {
  std::vector<uint32_t> out;
  if (!impl_->index || max_k <= 0) return out;
  const std::size_t k = std::min<std::size_t>(static_cast<std::size_t>(max_k), impl_->ids.size());
  float q[3] = {static_cast<float>(query.x), static_cast<float>(query.y),
                static_cast<float>(query.z)};
  flann::Matrix<float> qm(q, 1, 3);
  std::vector<std::vector<size_t>> idx;
  std::vector<std::vector<float>> dist;
  flann::SearchParams params(flann::FLANN_CHECKS_UNLIMITED);
  params.sorted = true;
  impl_->index->knnSearch(qm, idx, dist, k, params);
  for (size_t i : idx[0]) out.push_back(impl_->ids[i]);
  return out;
}

}  // namespace prt
