/* Another vendor's DDS (Eclipse Cyclone DDS) talking to bsn with types generated from the same idl/bsn.idl.
 * Usage: bsn_cyclone_peer DOMAIN NODE WANT TIMEOUT_S [LONG_ID_CHARS]
 * Publishes static raw samples of node NODE on bsn/raw at 100 Hz (as a third-party sensor driver would) and reads
 * bsn/orientation until WANT orientations of segment NODE with unit quaternions have arrived. Exit 0 on success.
 * With LONG_ID_CHARS, every tenth tick it also publishes a sample whose node_id is that many characters long: legal
 * for the IDL's unbounded string, and beyond the 255 characters fastddsgen's generated key code can hold. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bsn.h"
#include "dds/dds.h"

int main(int argc, char** argv) {
  if (argc != 5 && argc != 6) {
    fprintf(stderr, "usage: %s DOMAIN NODE WANT TIMEOUT_S [LONG_ID_CHARS]\n", argv[0]);
    return 2;
  }
  const dds_domainid_t domain = (dds_domainid_t)atoi(argv[1]);
  const char* node = argv[2];
  const int want = atoi(argv[3]);
  const double timeout_s = atof(argv[4]);
  const int long_id_chars = argc == 6 ? atoi(argv[5]) : 0;

  const dds_entity_t participant = dds_create_participant(domain, NULL, NULL);
  if (participant < 0) return 3;
  const dds_entity_t raw_topic = dds_create_topic(participant, &bsn_RawSample_desc, "bsn/raw", NULL, NULL);
  const dds_entity_t ori_topic = dds_create_topic(participant, &bsn_Orientation_desc, "bsn/orientation", NULL, NULL);
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 64);
  const dds_entity_t writer = dds_create_writer(participant, raw_topic, qos, NULL);
  const dds_entity_t reader = dds_create_reader(participant, ori_topic, qos, NULL);
  dds_delete_qos(qos);
  if (writer < 0 || reader < 0) return 3;

  bsn_RawSample raw;
  memset(&raw, 0, sizeof raw);
  raw.node_id = (char*)node;
  raw.acc[2] = 9.80665; /* level, at rest */
  raw.mag[1] = 21.5;    /* north and down, uT (ENU) */
  raw.mag[2] = -44.0;
  raw.channels = bsn_CHANNEL_ACC | bsn_CHANNEL_GYR | bsn_CHANNEL_MAG;

  bsn_RawSample hostile = raw;
  char* long_id = NULL;
  if (long_id_chars > 0) {
    long_id = malloc((size_t)long_id_chars + 1);
    if (!long_id) return 3;
    memset(long_id, 'x', (size_t)long_id_chars);
    long_id[long_id_chars] = '\0';
    hostile.node_id = long_id;
  }
  int hostile_sent = 0;

  void* samples[16] = {0};
  dds_sample_info_t infos[16];
  int got = 0, bad = 0;
  const dds_time_t start = dds_time();
  const dds_time_t end = start + (dds_time_t)(timeout_s * 1e9);
  for (unsigned long long k = 0; got < want && dds_time() < end; ++k) {
    raw.seq = k;
    raw.timestamp_ns = (unsigned long long)(start + (dds_time_t)k * DDS_MSECS(10));
    dds_write(writer, &raw);
    if (long_id && k % 10 == 0) {
      hostile.seq = k;
      hostile.timestamp_ns = raw.timestamp_ns;
      if (dds_write(writer, &hostile) == DDS_RETCODE_OK) hostile_sent++;
    }
    const int n = dds_take(reader, samples, infos, 16, 16);
    for (int i = 0; i < n; i++) {
      if (!infos[i].valid_data) continue;
      const bsn_Orientation* o = samples[i];
      if (strcmp(o->segment, node) != 0) continue;
      const double norm =
          sqrt(o->quat[0] * o->quat[0] + o->quat[1] * o->quat[1] + o->quat[2] * o->quat[2] + o->quat[3] * o->quat[3]);
      if (fabs(norm - 1.0) > 1e-6) bad++;
      got++;
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    const dds_duration_t wait = start + (dds_time_t)(k + 1) * DDS_MSECS(10) - dds_time();
    if (wait > 0) dds_sleepfor(wait);
  }
  printf("cyclone peer: %d orientations of '%s' received, %d not unit\n", got, node, bad);
  if (long_id) printf("cyclone peer: %d samples with a %d-character node id sent\n", hostile_sent, long_id_chars);
  dds_delete(participant);
  free(long_id);
  return got >= want && bad == 0 ? 0 : 1;
}
