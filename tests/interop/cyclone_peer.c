/* An independent DDS peer for tarmac's interop test, written against Cyclone DDS with types that
 * Cyclone's idlc generated from tarmac's own idl/ files.
 *
 *   tarmac-cyclone-peer DOMAIN OUT_DIR
 *
 * 1. waits (up to 30 s) for one nav_msgs/OccupancyGrid on rt/tarmac/costmap (reliable, transient
 *    local) and writes every field of it to OUT_DIR/costmap_received.txt;
 * 2. publishes one sensor_msgs/PointCloud2 on rt/tarmac/lidar/front/points (reliable) whose every
 *    field is set to a non-default value, writes every field of what it sent to
 *    OUT_DIR/points_sent.txt, and waits until the reader acknowledged it.
 * The test compares those files with tarmac's own rendering, field by field. The rendering format
 * (one "path=value" line per field, floats as C99 %a hex, byte sequences as hex) is shared with
 * tests/support/msg_dump.cpp. Exit 0 on success, 1 on any failure (with a reason on stderr). */

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dds/dds.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"

#define FAIL(...)                      \
  do {                                 \
    fprintf(stderr, "cyclone-peer: "); \
    fprintf(stderr, __VA_ARGS__);      \
    fprintf(stderr, "\n");             \
    exit(1);                           \
  } while (0)

static void dump_header(FILE* f, const std_msgs_msg_dds__Header_* h) {
  fprintf(f, "header.stamp.sec=%d\n", (int)h->stamp.sec);
  fprintf(f, "header.stamp.nanosec=%u\n", (unsigned)h->stamp.nanosec);
  fprintf(f, "header.frame_id=%s\n", h->frame_id ? h->frame_id : "");
}

static void dump_pose(FILE* f, const char* prefix, const geometry_msgs_msg_dds__Pose_* p) {
  fprintf(f, "%s.position.x=%a\n", prefix, p->position.x);
  fprintf(f, "%s.position.y=%a\n", prefix, p->position.y);
  fprintf(f, "%s.position.z=%a\n", prefix, p->position.z);
  fprintf(f, "%s.orientation.x=%a\n", prefix, p->orientation.x);
  fprintf(f, "%s.orientation.y=%a\n", prefix, p->orientation.y);
  fprintf(f, "%s.orientation.z=%a\n", prefix, p->orientation.z);
  fprintf(f, "%s.orientation.w=%a\n", prefix, p->orientation.w);
}

static void dump_bytes(FILE* f, const char* name, const uint8_t* bytes, uint32_t n) {
  fprintf(f, "%s.size=%u\n%s=", name, (unsigned)n, name);
  for (uint32_t i = 0; i < n; ++i) fprintf(f, "%02x", bytes[i]);
  fprintf(f, "\n");
}

static void dump_grid(FILE* f, const nav_msgs_msg_dds__OccupancyGrid_* g) {
  dump_header(f, &g->header);
  fprintf(f, "info.map_load_time.sec=%d\n", (int)g->info.map_load_time.sec);
  fprintf(f, "info.map_load_time.nanosec=%u\n", (unsigned)g->info.map_load_time.nanosec);
  fprintf(f, "info.resolution=%a\n", (double)g->info.resolution);
  fprintf(f, "info.width=%u\n", (unsigned)g->info.width);
  fprintf(f, "info.height=%u\n", (unsigned)g->info.height);
  dump_pose(f, "info.origin", &g->info.origin);
  dump_bytes(f, "data", (const uint8_t*)g->data._buffer, g->data._length);
}

static void dump_cloud(FILE* f, const sensor_msgs_msg_dds__PointCloud2_* c) {
  dump_header(f, &c->header);
  fprintf(f, "height=%u\n", (unsigned)c->height);
  fprintf(f, "width=%u\n", (unsigned)c->width);
  fprintf(f, "fields.size=%u\n", (unsigned)c->fields._length);
  for (uint32_t i = 0; i < c->fields._length; ++i) {
    const sensor_msgs_msg_dds__PointField_* pf = &c->fields._buffer[i];
    fprintf(f, "fields[%u].name=%s\n", (unsigned)i, pf->name ? pf->name : "");
    fprintf(f, "fields[%u].offset=%u\n", (unsigned)i, (unsigned)pf->offset);
    fprintf(f, "fields[%u].datatype=%u\n", (unsigned)i, (unsigned)pf->datatype);
    fprintf(f, "fields[%u].count=%u\n", (unsigned)i, (unsigned)pf->count);
  }
  fprintf(f, "is_bigendian=%d\n", c->is_bigendian ? 1 : 0);
  fprintf(f, "point_step=%u\n", (unsigned)c->point_step);
  fprintf(f, "row_step=%u\n", (unsigned)c->row_step);
  dump_bytes(f, "data", c->data._buffer, c->data._length);
  fprintf(f, "is_dense=%d\n", c->is_dense ? 1 : 0);
}

static FILE* open_out(const char* dir, const char* name) {
  char path[4096];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE* f = fopen(path, "w");
  if (!f) FAIL("cannot write %s", path);
  return f;
}

/* A cloud in an odd but legal layout: big-endian, padded points and rows, two rows, mixed
 * datatypes, so that tarmac's parser sees something other than its own writer's layout. */
static void make_cloud(sensor_msgs_msg_dds__PointCloud2_* c) {
  static const struct {
    const char* name;
    uint32_t offset;
    uint8_t datatype;
  } fields[] = {
      {"x", 0, sensor_msgs_msg_PointField_Constants_FLOAT32},
      {"y", 4, sensor_msgs_msg_PointField_Constants_FLOAT32},
      {"z", 8, sensor_msgs_msg_PointField_Constants_FLOAT32},
      {"intensity", 16, sensor_msgs_msg_PointField_Constants_FLOAT32},
      {"ring", 20, sensor_msgs_msg_PointField_Constants_UINT16},
      {"t", 24, sensor_msgs_msg_PointField_Constants_FLOAT64},
  };
  const uint32_t nfields = sizeof fields / sizeof fields[0];
  memset(c, 0, sizeof *c);
  c->header.stamp.sec = 1700000123;
  c->header.stamp.nanosec = 456789012;
  c->header.frame_id = dds_string_dup("lidar_front");
  c->height = 2;
  c->width = 37;
  c->fields._length = c->fields._maximum = nfields;
  c->fields._buffer = dds_alloc(nfields * sizeof *c->fields._buffer);
  c->fields._release = true;
  for (uint32_t i = 0; i < nfields; ++i) {
    c->fields._buffer[i].name = dds_string_dup(fields[i].name);
    c->fields._buffer[i].offset = fields[i].offset;
    c->fields._buffer[i].datatype = fields[i].datatype;
    c->fields._buffer[i].count = 1;
  }
  c->is_bigendian = true;
  c->point_step = 32;
  c->row_step = c->point_step * c->width + 8; /* row padding */
  c->is_dense = false;
  const uint32_t n = c->row_step * c->height;
  c->data._length = c->data._maximum = n;
  c->data._buffer = dds_alloc(n);
  c->data._release = true;
  uint32_t state = 2463534242u; /* xorshift32: arbitrary but reproducible bytes */
  for (uint32_t i = 0; i < n; ++i) {
    state ^= state << 13;
    state ^= state >> 17;
    state ^= state << 5;
    c->data._buffer[i] = (uint8_t)(state >> 24);
  }
}

int main(int argc, char** argv) {
  if (argc != 3) FAIL("usage: tarmac-cyclone-peer DOMAIN OUT_DIR");
  const dds_domainid_t domain = (dds_domainid_t)atoi(argv[1]);
  const char* out_dir = argv[2];

  const dds_entity_t participant = dds_create_participant(domain, NULL, NULL);
  if (participant < 0) FAIL("create participant: %s", dds_strretcode(-participant));

  dds_qos_t* grid_qos = dds_create_qos();
  dds_qset_reliability(grid_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(grid_qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(grid_qos, DDS_HISTORY_KEEP_LAST, 1);
  const dds_entity_t grid_topic = dds_create_topic(
      participant, &nav_msgs_msg_dds__OccupancyGrid__desc, "rt/tarmac/costmap", NULL, NULL);
  if (grid_topic < 0) FAIL("create costmap topic: %s", dds_strretcode(-grid_topic));
  const dds_entity_t grid_reader = dds_create_reader(participant, grid_topic, grid_qos, NULL);
  if (grid_reader < 0) FAIL("create costmap reader: %s", dds_strretcode(-grid_reader));

  dds_qos_t* cloud_qos = dds_create_qos();
  dds_qset_reliability(cloud_qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(cloud_qos, DDS_HISTORY_KEEP_LAST, 1);
  const dds_entity_t cloud_topic =
      dds_create_topic(participant, &sensor_msgs_msg_dds__PointCloud2__desc,
                       "rt/tarmac/lidar/front/points", NULL, NULL);
  if (cloud_topic < 0) FAIL("create points topic: %s", dds_strretcode(-cloud_topic));
  const dds_entity_t cloud_writer = dds_create_writer(participant, cloud_topic, cloud_qos, NULL);
  if (cloud_writer < 0) FAIL("create points writer: %s", dds_strretcode(-cloud_writer));

  /* 1. One costmap. */
  const dds_entity_t waitset = dds_create_waitset(participant);
  const dds_entity_t readcond = dds_create_readcondition(grid_reader, DDS_ANY_STATE);
  dds_waitset_attach(waitset, readcond, 0);
  if (dds_waitset_wait(waitset, NULL, 0, DDS_SECS(30)) <= 0) FAIL("no costmap within 30 s");
  void* samples[1] = {NULL};
  dds_sample_info_t info;
  if (dds_take(grid_reader, samples, &info, 1, 1) != 1 || !info.valid_data) FAIL("take costmap");
  FILE* f = open_out(out_dir, "costmap_received.txt");
  dump_grid(f, (const nav_msgs_msg_dds__OccupancyGrid_*)samples[0]);
  fclose(f);
  dds_return_loan(grid_reader, samples, 1);

  /* 2. One point cloud, after tarmac's reader matched, acknowledged before exit. */
  dds_publication_matched_status_t matched = {0};
  for (int i = 0; i < 3000 && matched.current_count == 0; ++i) {
    dds_get_publication_matched_status(cloud_writer, &matched);
    if (matched.current_count == 0) dds_sleepfor(DDS_MSECS(10));
  }
  if (matched.current_count == 0) FAIL("tarmac's points reader never matched");
  sensor_msgs_msg_dds__PointCloud2_ cloud;
  make_cloud(&cloud);
  f = open_out(out_dir, "points_sent.txt");
  dump_cloud(f, &cloud);
  fclose(f);
  const dds_return_t rc = dds_write(cloud_writer, &cloud);
  if (rc != DDS_RETCODE_OK) FAIL("write points: %s", dds_strretcode(rc));
  if (dds_wait_for_acks(cloud_writer, DDS_SECS(10)) != DDS_RETCODE_OK)
    FAIL("points not acknowledged");
  sensor_msgs_msg_dds__PointCloud2__free(&cloud, DDS_FREE_CONTENTS);

  dds_delete_qos(grid_qos);
  dds_delete_qos(cloud_qos);
  dds_delete(participant);
  return 0;
}
