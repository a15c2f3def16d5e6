/* tarmac-cyclone-replay: a client of tarmacd on another DDS implementation (Cyclone DDS), as a
 * ROS 2 LiDAR driver and planner in other processes would be. It replays a KITTI-layout sequence
 * (scans/NNNNNN.bin float32 x,y,z,intensity in the sensor frame, poses.txt T_world_sensor,
 * times.txt) over UDP with ROS 2 types and QoS, and subscribes to what tarmacd publishes:
 *
 *   - with --layout, tarmac-sim's organised sweeps (organised/NNNNNN.bin, rows = beams, lowest
 *     first) go out as a spinning LiDAR's driver sends them: rows = beams (ouster-ros), rows =
 *     firings with one column per laser (velodyne's organize_cloud), or a list of the returns in
 *     firing order (HesaiLidar_ROS_2.0, velodyne without organize_cloud); NaN or (0, 0, 0) where
 *     a beam returned nothing (--marker), a uint16 `ring` with --ring; the point laid out as
 *     velodyne's PointXYZIR (x, y, z at 0, intensity at 16, ring at 20, 32 bytes with padding);
 *   - sensor_msgs/PointCloud2 on the LiDAR topic, best effort, keep last 5 (rclcpp's
 *     SensorDataQoS), stamped with the wall clock on a grid of 1/rate;
 *   - geometry_msgs/PoseWithCovarianceStamped on the pose topic, reliable, keep last 100, one per
 *     scan at the scan's stamp (the base frame is taken as the sensor frame: run tarmacd with an
 *     identity extrinsic, as the shipped config has);
 *   - nav_msgs/OccupancyGrid from the costmap topic (reliable, transient local): the latency of
 *     each scan is the time from its stamp to the first costmap carrying that stamp, received;
 *   - tarmac_msgs/CycleReport from the diagnostics topic: points integrated and drop counters.
 *
 * Prints a summary (scans sent, costmaps received, latency p50/p99/max, points integrated against
 * points sent, tarmacd's transport drop counters) and writes it as JSON with --json.
 * Exit 0 when it ran (whatever the losses), 1 on a usage or DDS error, 2 when nothing matched.
 * Keep DDS on loopback: CYCLONEDDS_URI=file://$PWD/config/cyclonedds_localhost.xml. */

#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dds/dds.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"
#include "tarmac_msgs.h"

#define FAIL(...)                               \
  do {                                          \
    fprintf(stderr, "tarmac-cyclone-replay: "); \
    fprintf(stderr, __VA_ARGS__);               \
    fprintf(stderr, "\n");                      \
    exit(1);                                    \
  } while (0)

typedef struct {
  const char* dataset;
  const char* json;
  const char* lidar_topic;
  const char* pose_topic;
  const char* costmap_topic;
  const char* diagnostics_topic;
  const char* frame_id;
  const char* pose_frame_id;
  int domain;
  double rate_hz;
  long max_scans;
  double idle_s;
  double wait_s;
  long tail_scans;
  long head_scans;
  const char* layout; /* NULL: scans/ as they are; "beams", "firings", "list": organised/ */
  int ring;
  int zero_marker;
  long pose_readers;
  double sensor_height; /* the base lies this far below the sensor, along the sensor's z */
} Options;

static void usage(FILE* out) {
  fprintf(out,
          "usage: tarmac-cyclone-replay --dataset DIR [options]\n"
          "  --domain N               DDS domain (default 0)\n"
          "  --rate-hz HZ             scans per second (default 10)\n"
          "  --scans N                at most N scans (default: all)\n"
          "  --lidar-topic T          default rt/tarmac/lidar/front/points\n"
          "  --frame-id F             the cloud's header.frame_id (default lidar_front)\n"
          "  --pose-topic T           default rt/tarmac/pose (frame --pose-frame-id, default map)\n"
          "  --sensor-height M        the pose sent is the base's, M below the sensor along its z\n"
          "                           (tarmacd's extrinsic z; default 0: the base is the sensor)\n"
          "  --costmap-topic T        default rt/tarmac/costmap\n"
          "  --diagnostics-topic T    default rt/tarmac/diagnostics\n"
          "  --idle-s S               wait after the last scan for its costmap (default 2)\n"
          "  --head-scans N           first N short scans (the first cloud's first 2000 points):\n"
          "                           a receiver that gets one has a reference, so it sees any\n"
          "                           later loss as a gap in sequence numbers (default 0)\n"
          "  --tail-scans N           then N short scans (the last cloud's first 2000 points, one\n"
          "                           datagram each): a receiver sees losses at the end of the\n"
          "                           stream as a gap in sequence numbers (default 0)\n"
          "  --layout L               send organised/ (tarmac-sim) as 'beams' (rows = beams),\n"
          "                           'firings' (rows = firings) or 'list' (the returns only)\n"
          "  --ring                   with --layout: a uint16 ring field (0 = lowest beam)\n"
          "  --marker nan|zero        with --layout beams|firings: a beam without return as NaN\n"
          "                           (default) or (0, 0, 0)\n"
          "  --pose-readers N         wait until N readers match the pose topic (default 1)\n"
          "  --wait-s S               wait for tarmacd's readers to match (default 20)\n"
          "  --json FILE              the summary as JSON\n");
}

static int64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void sleep_ns(int64_t ns) {
  if (ns <= 0) return;
  struct timespec ts = {(time_t)(ns / 1000000000LL), (long)(ns % 1000000000LL)};
  nanosleep(&ts, NULL);
}

static builtin_interfaces_msg_dds__Time_ to_time(int64_t ns) {
  builtin_interfaces_msg_dds__Time_ t;
  t.sec = (int32_t)(ns / 1000000000LL);
  t.nanosec = (uint32_t)(ns % 1000000000LL);
  return t;
}

static int64_t from_time(const builtin_interfaces_msg_dds__Time_* t) {
  return (int64_t)t->sec * 1000000000LL + t->nanosec;
}

/* Reads a whole file; NULL when it cannot. */
static uint8_t* read_file(const char* path, uint32_t* size) {
  FILE* f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  const long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  uint8_t* buf = malloc(n > 0 ? (size_t)n : 1);
  if (!buf || fread(buf, 1, (size_t)n, f) != (size_t)n) {
    fclose(f);
    free(buf);
    return NULL;
  }
  fclose(f);
  *size = (uint32_t)n;
  return buf;
}

/* Rotation matrix (row-major 3x3) to a unit quaternion (x, y, z, w). */
static void to_quaternion(const double R[9], double q[4]) {
  const double tr = R[0] + R[4] + R[8];
  if (tr > 0) {
    const double s = sqrt(tr + 1.0) * 2;
    q[3] = 0.25 * s;
    q[0] = (R[7] - R[5]) / s;
    q[1] = (R[2] - R[6]) / s;
    q[2] = (R[3] - R[1]) / s;
  } else if (R[0] > R[4] && R[0] > R[8]) {
    const double s = sqrt(1.0 + R[0] - R[4] - R[8]) * 2;
    q[3] = (R[7] - R[5]) / s;
    q[0] = 0.25 * s;
    q[1] = (R[1] + R[3]) / s;
    q[2] = (R[2] + R[6]) / s;
  } else if (R[4] > R[8]) {
    const double s = sqrt(1.0 + R[4] - R[0] - R[8]) * 2;
    q[3] = (R[2] - R[6]) / s;
    q[0] = (R[1] + R[3]) / s;
    q[1] = 0.25 * s;
    q[2] = (R[5] + R[7]) / s;
  } else {
    const double s = sqrt(1.0 + R[8] - R[0] - R[4]) * 2;
    q[3] = (R[3] - R[1]) / s;
    q[0] = (R[2] + R[6]) / s;
    q[1] = (R[5] + R[7]) / s;
    q[2] = 0.25 * s;
  }
  const double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  for (int i = 0; i < 4; ++i) q[i] /= n;
}

static int cmp_double(const void* a, const void* b) {
  const double x = *(const double*)a, y = *(const double*)b;
  return (x > y) - (x < y);
}

static double percentile(const double* sorted, long n, double q) {
  if (n == 0) return 0.0;
  long k = (long)ceil(q * (double)n) - 1;
  if (k < 0) k = 0;
  if (k >= n) k = n - 1;
  return sorted[k];
}

/* What the subscriptions saw. */
typedef struct {
  int64_t* stamps;    /* sent scan stamps, by scan */
  double* latency_ms; /* by scan: stamp -> first costmap with that stamp received; <0 none */
  long scans;
  long costmaps;
  uint64_t points_integrated;
  /* tarmacd's transport.scan_lost.*, transport.scan_rejected.*, and scans it shed while its
     cycle lagged: queue.scan_overflow and scan.shed_pending_full */
  uint64_t lost, rejected, overflow;
  long reports;
} Seen;

static void take_costmaps(dds_entity_t reader, Seen* seen) {
  void* samples[8] = {NULL};
  dds_sample_info_t infos[8];
  int n;
  while ((n = dds_take(reader, samples, infos, 8, 8)) > 0) {
    const int64_t t = now_ns();
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const nav_msgs_msg_dds__OccupancyGrid_* g = samples[i];
      ++seen->costmaps;
      const int64_t stamp = from_time(&g->header.stamp);
      for (long k = seen->scans - 1; k >= 0; --k) {
        if (seen->stamps[k] == stamp) {
          if (seen->latency_ms[k] < 0) seen->latency_ms[k] = (double)(t - stamp) / 1e6;
          break;
        }
      }
    }
    dds_return_loan(reader, samples, n);
  }
}

static void take_reports(dds_entity_t reader, Seen* seen) {
  void* samples[8] = {NULL};
  dds_sample_info_t infos[8];
  int n;
  while ((n = dds_take(reader, samples, infos, 8, 8)) > 0) {
    for (int i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const tarmac_msgs_msg_dds__CycleReport_* r = samples[i];
      ++seen->reports;
      seen->points_integrated += r->points_in;
      uint64_t lost = 0, rejected = 0, overflow = 0;
      for (uint32_t j = 0; j < r->drops._length; ++j) {
        const char* reason = r->drops._buffer[j].reason;
        const uint64_t total = r->drops._buffer[j].total;
        if (strncmp(reason, "transport.scan_lost.", 20) == 0) lost += total;
        if (strncmp(reason, "transport.scan_rejected.", 24) == 0) rejected += total;
        if (strcmp(reason, "queue.scan_overflow") == 0 ||
            strcmp(reason, "scan.shed_pending_full") == 0) {
          overflow += total;
        }
      }
      seen->lost = lost;
      seen->rejected = rejected;
      seen->overflow = overflow;
    }
    dds_return_loan(reader, samples, n);
  }
}

/* Sleeps until `deadline_ns` on the wall clock, taking what arrives meanwhile. */
static void serve_until(int64_t deadline_ns, dds_entity_t costmaps, dds_entity_t reports,
                        Seen* seen) {
  for (;;) {
    take_costmaps(costmaps, seen);
    take_reports(reports, seen);
    const int64_t left = deadline_ns - now_ns();
    if (left <= 0) return;
    sleep_ns(left < 1000000 ? left : 1000000);
  }
}

/* One scan as the LiDAR topic carries it. */
typedef struct {
  sensor_msgs_msg_dds__PointField_ fields[5];
  uint32_t field_count;
  uint8_t* data; /* malloc'd */
  uint32_t height, width, point_step;
  uint32_t points; /* the returns in it */
} Scan;

static void set_field(Scan* s, const char* name, uint32_t offset, uint8_t datatype) {
  sensor_msgs_msg_dds__PointField_* f = &s->fields[s->field_count++];
  f->name = (char*)name;
  f->offset = offset;
  f->datatype = datatype;
  f->count = 1;
}

/* scans/NNNNNN.bin as it is: height 1, float32 x, y, z, intensity; a short scan keeps the first
 * 2000 points. */
static void load_list_scan(const Options* o, long scan, int short_scan, Scan* out) {
  char path[4096];
  snprintf(path, sizeof path, "%s/scans/%06ld.bin", o->dataset, scan);
  uint32_t size = 0;
  out->data = read_file(path, &size);
  if (!out->data) FAIL("cannot read %s", path);
  uint32_t n = size / 16u;
  if (short_scan && n > 2000) n = 2000;
  static const char* names[4] = {"x", "y", "z", "intensity"};
  out->field_count = 0;
  for (uint32_t f = 0; f < 4; ++f) {
    set_field(out, names[f], 4 * f, sensor_msgs_msg_PointField_Constants_FLOAT32);
  }
  out->height = 1;
  out->width = n;
  out->point_step = 16;
  out->points = n;
}

static int is_return(const float* cell) {
  return isfinite(cell[0]) && isfinite(cell[1]) && isfinite(cell[2]) &&
         !(cell[0] == 0.0f && cell[1] == 0.0f && cell[2] == 0.0f);
}

/* organised/NNNNNN.bin (rows = beams, lowest first, by columns = firings) in o->layout, each
 * point laid out as velodyne's PointXYZIR: x, y, z at 0, 4, 8, intensity at 16, ring at 20,
 * 32 bytes. rows = beams goes out top first with ring 0 at the top (ouster-ros); rows = firings
 * with the lasers lowest first, ring 0 the lowest (velodyne); the list in firing order, each
 * firing top first, ring 0 at the top (Hesai). A short scan is the list of the first 2000
 * returns. */
static void load_organised_scan(const Options* o, long rows, long cols, long scan, int short_scan,
                                Scan* out) {
  char path[4096];
  snprintf(path, sizeof path, "%s/organised/%06ld.bin", o->dataset, scan);
  uint32_t size = 0;
  float* grid = (float*)read_file(path, &size);
  if (!grid || size != (uint32_t)(rows * cols * 16))
    FAIL("%s: not %ld x %ld cells", path, rows, cols);
  const int list = short_scan || strcmp(o->layout, "list") == 0;
  const int firings = !list && strcmp(o->layout, "firings") == 0;
  out->field_count = 0;
  set_field(out, "x", 0, sensor_msgs_msg_PointField_Constants_FLOAT32);
  set_field(out, "y", 4, sensor_msgs_msg_PointField_Constants_FLOAT32);
  set_field(out, "z", 8, sensor_msgs_msg_PointField_Constants_FLOAT32);
  set_field(out, "intensity", 16, sensor_msgs_msg_PointField_Constants_FLOAT32);
  if (o->ring) set_field(out, "ring", 20, sensor_msgs_msg_PointField_Constants_UINT16);
  out->point_step = 32;
  out->data = calloc((size_t)(rows * cols), 32);
  if (!out->data) FAIL("out of memory");
  uint32_t n = 0;
  out->points = 0;
  const long lines = firings || list ? cols : rows, along = firings || list ? rows : cols;
  for (long a = 0; a < lines; ++a) {
    for (long b = 0; b < along; ++b) {
      /* the source cell (beam, column) and its ring */
      const long beam = firings ? b : list ? rows - 1 - b : rows - 1 - a;
      const long col = firings || list ? a : b;
      const uint16_t ring = (uint16_t)(firings ? beam : rows - 1 - beam);
      const float* cell = &grid[(beam * cols + col) * 4];
      const int back = is_return(cell);
      if (list && (!back || (short_scan && out->points >= 2000))) continue;
      uint8_t* p = out->data + (size_t)n * 32;
      const float none = o->zero_marker ? 0.0f : NAN;
      const float xyz[3] = {back ? cell[0] : none, back ? cell[1] : none, back ? cell[2] : none};
      memcpy(p, xyz, 12);
      memcpy(p + 16, &cell[3], 4);
      if (o->ring) memcpy(p + 20, &ring, 2);
      ++n;
      out->points += back ? 1u : 0u;
    }
  }
  out->height = list ? 1u : (uint32_t)lines;
  out->width = list ? n : (uint32_t)along;
  free(grid);
}

static void organised_shape(const char* dataset, long* rows, long* cols) {
  char path[4096];
  snprintf(path, sizeof path, "%s/organised/shape.txt", dataset);
  FILE* f = fopen(path, "r");
  if (!f || fscanf(f, "%ld %ld", rows, cols) != 2 || *rows < 2 || *cols < 2 ||
      *rows * *cols > (1L << 24)) {
    FAIL("--layout needs a tarmac-sim dataset: cannot read rows and cols from %s", path);
  }
  fclose(f);
}

static dds_entity_t make_topic(dds_entity_t participant, const dds_topic_descriptor_t* desc,
                               const char* name) {
  const dds_entity_t topic = dds_create_topic(participant, desc, name, NULL, NULL);
  if (topic < 0) FAIL("create topic %s: %s", name, dds_strretcode(-topic));
  return topic;
}

static void parse(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const char* v = i + 1 < argc ? argv[i + 1] : NULL;
    if (strcmp(a, "--help") == 0 || strcmp(a, "-h") == 0) {
      usage(stdout);
      exit(0);
    }
    if (strcmp(a, "--ring") == 0) {
      o->ring = 1;
      continue;
    }
    if (!v) {
      fprintf(stderr, "tarmac-cyclone-replay: %s needs a value\n", a);
      usage(stderr);
      exit(64);
    }
    char* end = NULL;
    if (strcmp(a, "--dataset") == 0)
      o->dataset = v;
    else if (strcmp(a, "--json") == 0)
      o->json = v;
    else if (strcmp(a, "--lidar-topic") == 0)
      o->lidar_topic = v;
    else if (strcmp(a, "--pose-topic") == 0)
      o->pose_topic = v;
    else if (strcmp(a, "--costmap-topic") == 0)
      o->costmap_topic = v;
    else if (strcmp(a, "--diagnostics-topic") == 0)
      o->diagnostics_topic = v;
    else if (strcmp(a, "--frame-id") == 0)
      o->frame_id = v;
    else if (strcmp(a, "--pose-frame-id") == 0)
      o->pose_frame_id = v;
    else if (strcmp(a, "--domain") == 0)
      o->domain = (int)strtol(v, &end, 10);
    else if (strcmp(a, "--sensor-height") == 0)
      o->sensor_height = strtod(v, &end);
    else if (strcmp(a, "--rate-hz") == 0)
      o->rate_hz = strtod(v, &end);
    else if (strcmp(a, "--scans") == 0)
      o->max_scans = strtol(v, &end, 10);
    else if (strcmp(a, "--idle-s") == 0)
      o->idle_s = strtod(v, &end);
    else if (strcmp(a, "--wait-s") == 0)
      o->wait_s = strtod(v, &end);
    else if (strcmp(a, "--tail-scans") == 0)
      o->tail_scans = strtol(v, &end, 10);
    else if (strcmp(a, "--head-scans") == 0)
      o->head_scans = strtol(v, &end, 10);
    else if (strcmp(a, "--pose-readers") == 0)
      o->pose_readers = strtol(v, &end, 10);
    else if (strcmp(a, "--layout") == 0 &&
             (strcmp(v, "beams") == 0 || strcmp(v, "firings") == 0 || strcmp(v, "list") == 0))
      o->layout = v;
    else if (strcmp(a, "--marker") == 0 && (strcmp(v, "nan") == 0 || strcmp(v, "zero") == 0))
      o->zero_marker = strcmp(v, "zero") == 0;
    else {
      fprintf(stderr, "tarmac-cyclone-replay: unknown option %s\n", a);
      usage(stderr);
      exit(64);
    }
    if (end != NULL && *end != '\0') {
      fprintf(stderr, "tarmac-cyclone-replay: %s: not a number: %s\n", a, v);
      exit(64);
    }
    ++i;
  }
  if (!o->dataset) {
    usage(stderr);
    exit(64);
  }
  if (!(o->rate_hz > 0.0 && o->rate_hz <= 1000.0) || o->domain < 0 || o->domain > 232 ||
      !(o->idle_s >= 0.0) || !(o->wait_s >= 0.0) || o->max_scans < 0 || o->tail_scans < 0 ||
      o->tail_scans > 1000 || o->head_scans < 0 || o->head_scans > 1000 || o->pose_readers < 1 ||
      ((o->ring || o->zero_marker) && !o->layout)) {
    fprintf(stderr, "tarmac-cyclone-replay: a value is out of range\n");
    exit(64);
  }
}

/* poses.txt: one row-major 3x4 T_world_sensor per scan; at most max_scans (0: all). */
static double* read_poses(const char* dataset, long max_scans, long* scans) {
  char path[4096];
  snprintf(path, sizeof path, "%s/poses.txt", dataset);
  FILE* pf = fopen(path, "r");
  if (!pf) FAIL("cannot read %s", path);
  long capacity = 1024, n = 0;
  double* poses = malloc((size_t)capacity * 12 * sizeof(double));
  for (;;) {
    double row[12];
    int got = 0;
    for (; got < 12; ++got) {
      if (fscanf(pf, "%lf", &row[got]) != 1) break;
    }
    if (got < 12) break;
    if (n == capacity) {
      capacity *= 2;
      poses = realloc(poses, (size_t)capacity * 12 * sizeof(double));
    }
    memcpy(&poses[n * 12], row, sizeof row);
    ++n;
  }
  fclose(pf);
  if (max_scans > 0 && max_scans < n) n = max_scans;
  if (n == 0) FAIL("no poses in %s", path);
  *scans = n;
  return poses;
}

/* The participant, the two writers of a LiDAR driver and a localiser, the readers of tarmacd's
 * costmap and CycleReport, with rclcpp's QoS for each. */
typedef struct {
  dds_entity_t participant, cloud_writer, pose_writer, grid_reader, report_reader;
  dds_qos_t *sensor_qos, *pose_qos, *grid_qos, *report_qos;
} Endpoints;

static Endpoints create_endpoints(const Options* o) {
  Endpoints e;
  e.participant = dds_create_participant(o->domain, NULL, NULL);
  if (e.participant < 0) FAIL("create participant: %s", dds_strretcode(-e.participant));
  e.sensor_qos = dds_create_qos(); /* rclcpp::SensorDataQoS */
  dds_qset_reliability(e.sensor_qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(e.sensor_qos, DDS_HISTORY_KEEP_LAST, 5);
  e.pose_qos = dds_create_qos();
  dds_qset_reliability(e.pose_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(e.pose_qos, DDS_HISTORY_KEEP_LAST, 100);
  e.grid_qos = dds_create_qos();
  dds_qset_reliability(e.grid_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(e.grid_qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(e.grid_qos, DDS_HISTORY_KEEP_LAST, 1);
  e.report_qos = dds_create_qos();
  dds_qset_reliability(e.report_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(e.report_qos, DDS_HISTORY_KEEP_LAST, 100);
  const dds_entity_t p = e.participant;
  e.cloud_writer =
      dds_create_writer(p, make_topic(p, &sensor_msgs_msg_dds__PointCloud2__desc, o->lidar_topic),
                        e.sensor_qos, NULL);
  e.pose_writer = dds_create_writer(
      p, make_topic(p, &geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc, o->pose_topic),
      e.pose_qos, NULL);
  e.grid_reader = dds_create_reader(
      p, make_topic(p, &nav_msgs_msg_dds__OccupancyGrid__desc, o->costmap_topic), e.grid_qos, NULL);
  e.report_reader = dds_create_reader(
      p, make_topic(p, &tarmac_msgs_msg_dds__CycleReport__desc, o->diagnostics_topic), e.report_qos,
      NULL);
  if (e.cloud_writer < 0 || e.pose_writer < 0 || e.grid_reader < 0 || e.report_reader < 0) {
    FAIL("cannot create the writers and readers");
  }
  return e;
}

static void delete_endpoints(Endpoints* e) {
  dds_delete_qos(e->sensor_qos);
  dds_delete_qos(e->pose_qos);
  dds_delete_qos(e->grid_qos);
  dds_delete_qos(e->report_qos);
  dds_delete(e->participant);
}

/* Waits for tarmacd: both its readers and its costmap writer. 0, or 2 after a message. */
static int wait_for_tarmacd(const Options* o, const Endpoints* e) {
  const int64_t wait_until = now_ns() + (int64_t)(o->wait_s * 1e9);
  for (;;) {
    dds_publication_matched_status_t c = {0}, p = {0};
    dds_subscription_matched_status_t g = {0};
    dds_get_publication_matched_status(e->cloud_writer, &c);
    dds_get_publication_matched_status(e->pose_writer, &p);
    dds_get_subscription_matched_status(e->grid_reader, &g);
    if (c.current_count > 0 && p.current_count >= o->pose_readers && g.current_count > 0) return 0;
    if (now_ns() > wait_until) {
      fprintf(stderr, "tarmac-cyclone-replay: tarmacd did not match within %.0f s (domain %d)\n",
              o->wait_s, o->domain);
      return 2;
    }
    sleep_ns(10000000);
  }
}

/* The pose message of the base under a row-major 3x4 T_world_sensor at `stamp`: the sensor's
 * frame moved `sensor_height` down its own z (a sensor mounted on the vehicle's roof). */
static void fill_pose(geometry_msgs_msg_dds__PoseWithCovarianceStamped_* pose, const double* T,
                      double sensor_height, int64_t stamp, const char* frame_id) {
  memset(pose, 0, sizeof *pose);
  pose->header.stamp = to_time(stamp);
  pose->header.frame_id = (char*)frame_id;
  const double R[9] = {T[0], T[1], T[2], T[4], T[5], T[6], T[8], T[9], T[10]};
  double q[4];
  to_quaternion(R, q);
  pose->pose.pose.position.x = T[3] - sensor_height * T[2];
  pose->pose.pose.position.y = T[7] - sensor_height * T[6];
  pose->pose.pose.position.z = T[11] - sensor_height * T[10];
  pose->pose.pose.orientation.x = q[0];
  pose->pose.pose.orientation.y = q[1];
  pose->pose.pose.orientation.z = q[2];
  pose->pose.pose.orientation.w = q[3];
}

/* The PointCloud2 of a loaded scan at `stamp` (it borrows the scan's fields and bytes). */
static void fill_cloud(sensor_msgs_msg_dds__PointCloud2_* cloud, Scan* data, int64_t stamp,
                       const char* frame_id) {
  memset(cloud, 0, sizeof *cloud);
  cloud->header.stamp = to_time(stamp);
  cloud->header.frame_id = (char*)frame_id;
  cloud->height = data->height;
  cloud->width = data->width;
  cloud->fields._length = cloud->fields._maximum = data->field_count;
  cloud->fields._buffer = data->fields;
  cloud->is_bigendian = false;
  cloud->point_step = data->point_step;
  cloud->row_step = data->point_step * data->width;
  cloud->data._length = cloud->data._maximum = cloud->row_step * data->height;
  cloud->data._buffer = data->data;
  cloud->is_dense = data->points == data->height * data->width;
}

/* What was sent. */
typedef struct {
  long sent, write_errors;
  uint64_t points_sent, bytes_sent;
} Sent;

/* Sends the head scans, the sequence and the tail scans at rate_hz on the grid of the period, as
 * a LiDAR phase-locked to PTP would, serving tarmacd's costmaps and reports between them, and
 * then for idle_s. */
static Sent send_scans(const Options* o, const Endpoints* e, const double* poses, long scans,
                       long rows, long cols, Seen* seen) {
  const long total = o->head_scans + scans + o->tail_scans;
  const int64_t period_ns = (int64_t)llround(1e9 / o->rate_hz);
  const int64_t start_ns = (now_ns() / period_ns + 5) * period_ns;
  Sent out = {0, 0, 0, 0};
  for (long k = 0; k < total; ++k) {
    /* A head scan repeats the first pose, a tail scan the last one. */
    const long j = k - o->head_scans;
    const int short_scan = j < 0 || j >= scans;
    const long scan = j < 0 ? 0 : j < scans ? j : scans - 1;
    Scan data = {0};
    if (o->layout) {
      load_organised_scan(o, rows, cols, scan, short_scan, &data);
    } else {
      load_list_scan(o, scan, short_scan, &data);
    }
    const int64_t stamp = start_ns + k * period_ns;
    geometry_msgs_msg_dds__PoseWithCovarianceStamped_ pose;
    fill_pose(&pose, &poses[scan * 12], o->sensor_height, stamp, o->pose_frame_id);
    sensor_msgs_msg_dds__PointCloud2_ cloud;
    fill_cloud(&cloud, &data, stamp, o->frame_id);
    seen->stamps[k] = stamp;
    seen->scans = k + 1;
    serve_until(stamp, e->grid_reader, e->report_reader, seen);
    if (dds_write(e->pose_writer, &pose) != DDS_RETCODE_OK) ++out.write_errors;
    if (dds_write(e->cloud_writer, &cloud) != DDS_RETCODE_OK) ++out.write_errors;
    ++out.sent;
    out.points_sent += data.points;
    if (!short_scan) out.bytes_sent += cloud.data._length; /* the sequence's, for their mean */
    free(data.data);
  }
  serve_until(now_ns() + (int64_t)(o->idle_s * 1e9), e->grid_reader, e->report_reader, seen);
  return out;
}

/* The figures: printed, and with --json written. */
static void report(const Options* o, const Seen* seen, const Sent* s, long scans, long total) {
  double* lat = malloc((size_t)total * sizeof(double));
  long with_costmap = 0;
  for (long k = 0; k < total; ++k) {
    if (seen->latency_ms[k] >= 0) lat[with_costmap++] = seen->latency_ms[k];
  }
  /* Scans before the first that came back in a costmap: a receiver has no reference for losses
   * before the first sample it got from a writer (DDS counts a loss as a gap after it). */
  long first_back = -1;
  for (long k = 0; k < total && first_back < 0; ++k) {
    if (seen->latency_ms[k] >= 0) first_back = k;
  }
  qsort(lat, (size_t)with_costmap, sizeof(double), cmp_double);
  const double p50 = percentile(lat, with_costmap, 0.5), p99 = percentile(lat, with_costmap, 0.99);
  const double max = with_costmap ? lat[with_costmap - 1] : 0.0;
  const double share =
      s->points_sent ? (double)seen->points_integrated / (double)s->points_sent : 0.0;
  printf(
      "scans sent: %ld incl. %ld short head and %ld short tail scans (%.0f KB per cloud of the "
      "sequence on average, %.1f Hz, %ld write errors)\n",
      s->sent, o->head_scans, o->tail_scans, (double)s->bytes_sent / (double)scans / 1000.0,
      o->rate_hz, s->write_errors);
  printf("points integrated by tarmacd: %llu of %llu sent (%.2f %%)\n",
         (unsigned long long)seen->points_integrated, (unsigned long long)s->points_sent,
         100.0 * share);
  printf("tarmacd transport drops: lost %llu, rejected %llu, queue overflow %llu (%ld reports)\n",
         (unsigned long long)seen->lost, (unsigned long long)seen->rejected,
         (unsigned long long)seen->overflow, seen->reports);
  printf("costmaps received: %ld; scans with a costmap of their stamp: %ld (the first: scan %ld)\n",
         seen->costmaps, with_costmap, first_back);
  printf("scan stamp -> costmap received (ms): p50 %.1f  p99 %.1f  max %.1f\n", p50, p99, max);
  if (o->json) {
    FILE* j = fopen(o->json, "w");
    if (!j) FAIL("cannot write %s", o->json);
    fprintf(j,
            "{\"scans_sent\": %ld, \"bytes_per_cloud\": %.0f, \"rate_hz\": %g, "
            "\"write_errors\": %ld, \"points_sent\": %llu, \"points_integrated\": %llu, "
            "\"transport_lost\": %llu, \"transport_rejected\": %llu, \"queue_overflow\": %llu, "
            "\"costmaps_received\": %ld, \"scans_with_costmap\": %ld, \"first_scan_back\": %ld, "
            "\"latency_ms\": {\"p50\": %.3f, \"p99\": %.3f, \"max\": %.3f}}\n",
            s->sent, (double)s->bytes_sent / (double)scans, o->rate_hz, s->write_errors,
            (unsigned long long)s->points_sent, (unsigned long long)seen->points_integrated,
            (unsigned long long)seen->lost, (unsigned long long)seen->rejected,
            (unsigned long long)seen->overflow, seen->costmaps, with_costmap, first_back, p50, p99,
            max);
    fclose(j);
  }
  free(lat);
}

int main(int argc, char** argv) {
  Options o = {NULL,
               NULL,
               "rt/tarmac/lidar/front/points",
               "rt/tarmac/pose",
               "rt/tarmac/costmap",
               "rt/tarmac/diagnostics",
               "lidar_front",
               "map",
               0,
               10.0,
               0,
               2.0,
               20.0,
               0,
               0,
               NULL,
               0,
               0,
               1,
               0.0};
  parse(argc, argv, &o);
  long scans = 0;
  double* poses = read_poses(o.dataset, o.max_scans, &scans);
  long rows = 0, cols = 0;
  if (o.layout) organised_shape(o.dataset, &rows, &cols);

  Endpoints e = create_endpoints(&o);
  if (wait_for_tarmacd(&o, &e) != 0) return 2;

  Seen seen = {0};
  const long total = o.head_scans + scans + o.tail_scans;
  seen.stamps = calloc((size_t)total, sizeof(int64_t));
  seen.latency_ms = malloc((size_t)total * sizeof(double));
  for (long k = 0; k < total; ++k) seen.latency_ms[k] = -1.0;
  take_costmaps(e.grid_reader, &seen); /* a transient-local costmap of an earlier run */
  for (long k = 0; k < seen.scans; ++k) seen.latency_ms[k] = -1.0;

  const Sent sent = send_scans(&o, &e, poses, scans, rows, cols, &seen);
  report(&o, &seen, &sent, scans, total);
  delete_endpoints(&e);
  free(seen.stamps);
  free(seen.latency_ms);
  free(poses);
  return 0;
}
