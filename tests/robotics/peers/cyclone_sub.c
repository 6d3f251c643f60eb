/* A Cyclone DDS C subscriber of sensor_msgs/msg/Image (the IDL beside it, compiled by idlc).
 * Usage: cyclone_sub TOPIC COUNT OUTDIR TIMEOUT_S. Per sample: OUTDIR/N.bin (the pixel bytes) and one line
 * "sec nanosec frame_id width height encoding step" on stdout. Exit 0 once COUNT arrived, 1 at the timeout. */
#include <stdio.h>
#include <stdlib.h>

#include "dds/dds.h"
#include "sensor_msgs.h"

int main(int argc, char **argv) {
  if (argc != 5) {
    fprintf(stderr, "usage: %s TOPIC COUNT OUTDIR TIMEOUT_S\n", argv[0]);
    return 2;
  }
  int count = atoi(argv[2]), got = 0;
  dds_time_t end = dds_time() + (dds_duration_t)(atof(argv[4]) * 1e9);
  dds_entity_t pp = dds_create_participant(DDS_DOMAIN_DEFAULT, NULL, NULL);
  dds_entity_t tp = dds_create_topic(pp, &sensor_msgs_msg_dds__Image__desc, argv[1], NULL, NULL);
  dds_qos_t *qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 10);
  dds_entity_t rd = dds_create_reader(pp, tp, qos, NULL);
  dds_delete_qos(qos);
  if (pp < 0 || tp < 0 || rd < 0) {
    fprintf(stderr, "cyclone_sub: cannot create the participant, topic or reader\n");
    return 2;
  }
  while (got < count && dds_time() < end) {
    void *samples[1] = {NULL};
    dds_sample_info_t info[1];
    int n = dds_take(rd, samples, info, 1, 1);
    if (n > 0 && info[0].valid_data) {
      const sensor_msgs_msg_dds__Image_ *m = samples[0];
      char path[4096];
      snprintf(path, sizeof path, "%s/%d.bin", argv[3], got);
      FILE *f = fopen(path, "wb");
      fwrite(m->data._buffer, 1, m->data._length, f);
      fclose(f);
      printf("%d %u %s %u %u %s %u\n", m->header.stamp.sec, m->header.stamp.nanosec, m->header.frame_id, m->width,
             m->height, m->encoding, m->step);
      fflush(stdout);
      got++;
    }
    if (n > 0)
      dds_return_loan(rd, samples, n);
    else
      dds_sleepfor(DDS_MSECS(10));
  }
  dds_delete(pp);
  return got == count ? 0 : 1;
}
