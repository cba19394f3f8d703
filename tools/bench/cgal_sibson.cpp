// Reference Sibson coordinates with CGAL 5.5 (tools/bench/bench_sibson.py builds and runs this).
//
//     cgal_sibson INPUT OUTPUT [runs]
//
// INPUT (little-endian, native): int64 N, int64 M, N*3 float64 sites, M*3 float64 queries.
// Each run builds the Delaunay triangulation of the sites and computes the Sibson coordinates of
// every query with CGAL::sibson_natural_neighbor_coordinates_3 (Epick kernel: exact predicates,
// inexact constructions); both phases are timed separately with std::chrono::steady_clock.
// OUTPUT: int64 runs, runs float64 triangulation seconds, runs float64 coordinate seconds,
// int64 failed (queries CGAL reports outside the hull; their rows are empty), int64 nnz,
// then nnz (row, col, value) triplets as float64, columns = site indices in input order,
// values normalised to sum 1 per row (from the last run).

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>
#include <CGAL/natural_neighbor_coordinates_3.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <iterator>
#include <utility>
#include <vector>

typedef CGAL::Exact_predicates_inexact_constructions_kernel K;
typedef CGAL::Triangulation_vertex_base_with_info_3<std::int64_t, K> Vb;
typedef CGAL::Delaunay_triangulation_cell_base_3<K> Cb;
typedef CGAL::Triangulation_data_structure_3<Vb, Cb> Tds;
typedef CGAL::Delaunay_triangulation_3<K, Tds> Dt;
typedef K::Point_3 Point;
typedef K::FT FT;

static void die(const char* msg) {
  std::fprintf(stderr, "cgal_sibson: %s\n", msg);
  std::exit(1);
}

static void read_exact(std::FILE* f, void* buf, std::size_t bytes) {
  if (std::fread(buf, 1, bytes, f) != bytes) die("short read");
}

static void write_all(std::FILE* f, const void* buf, std::size_t bytes) {
  if (std::fwrite(buf, 1, bytes, f) != bytes) die("short write");
}

int main(int argc, char** argv) {
  if (argc < 3) die("usage: cgal_sibson INPUT OUTPUT [runs]");
  const int runs = argc > 3 ? std::atoi(argv[3]) : 1;
  if (runs < 1) die("runs must be >= 1");

  std::FILE* in = std::fopen(argv[1], "rb");
  if (!in) die("cannot open input");
  std::int64_t n = 0, m = 0;
  read_exact(in, &n, sizeof n);
  read_exact(in, &m, sizeof m);
  if (n < 4 || m < 0) die("bad header");
  std::vector<double> s(3 * n), q(3 * m);
  read_exact(in, s.data(), s.size() * sizeof(double));
  read_exact(in, q.data(), q.size() * sizeof(double));
  std::fclose(in);

  std::vector<std::pair<Point, std::int64_t>> sites;
  sites.reserve(n);
  for (std::int64_t i = 0; i < n; ++i)
    sites.emplace_back(Point(s[3 * i], s[3 * i + 1], s[3 * i + 2]), i);
  std::vector<Point> queries;
  queries.reserve(m);
  for (std::int64_t i = 0; i < m; ++i) queries.emplace_back(q[3 * i], q[3 * i + 1], q[3 * i + 2]);

  std::vector<double> t_tri(runs), t_coord(runs);
  std::vector<double> rows, cols, vals;
  std::vector<std::pair<Dt::Vertex_handle, FT>> nn;
  std::int64_t failed = 0;
  for (int run = 0; run < runs; ++run) {
    rows.clear();
    cols.clear();
    vals.clear();
    failed = 0;
    auto t0 = std::chrono::steady_clock::now();
    Dt dt(sites.begin(), sites.end());
    auto t1 = std::chrono::steady_clock::now();
    if (dt.dimension() != 3) die("sites are not in general 3D position");
    if (static_cast<std::int64_t>(dt.number_of_vertices()) != n) die("duplicate sites");
    for (std::int64_t i = 0; i < m; ++i) {
      nn.clear();
      FT norm;
      auto res = CGAL::sibson_natural_neighbor_coordinates_3(dt, queries[i], std::back_inserter(nn),
                                                             norm);
      if (!res.third) {
        ++failed;
        continue;
      }
      for (const auto& p : nn) {
        rows.push_back(static_cast<double>(i));
        cols.push_back(static_cast<double>(p.first->info()));
        vals.push_back(p.second / norm);
      }
    }
    auto t2 = std::chrono::steady_clock::now();
    t_tri[run] = std::chrono::duration<double>(t1 - t0).count();
    t_coord[run] = std::chrono::duration<double>(t2 - t1).count();
  }

  std::FILE* out = std::fopen(argv[2], "wb");
  if (!out) die("cannot open output");
  const std::int64_t r64 = runs, nnz = static_cast<std::int64_t>(vals.size());
  write_all(out, &r64, sizeof r64);
  write_all(out, t_tri.data(), runs * sizeof(double));
  write_all(out, t_coord.data(), runs * sizeof(double));
  write_all(out, &failed, sizeof failed);
  write_all(out, &nnz, sizeof nnz);
  std::vector<double> trip(3 * vals.size());
  for (std::size_t k = 0; k < vals.size(); ++k) {
    trip[3 * k] = rows[k];
    trip[3 * k + 1] = cols[k];
    trip[3 * k + 2] = vals[k];
  }
  write_all(out, trip.data(), trip.size() * sizeof(double));
  if (std::fclose(out) != 0) die("cannot close output");
  return 0;
}
