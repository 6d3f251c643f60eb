/* A Cyclone DDS C reader of the ROS 2 graph, as rmw_cyclonedds reads it (the IDL beside it, compiled by idlc):
 * ros_discovery_info (ParticipantEntitiesInfo, reliable, transient local), rt/diagnostics (DiagnosticArray),
 * rt/rosout (rcl_interfaces/Log, reliable, transient local, as rcl subscribes it) and
 * the DDS built-in topics DCPSParticipant, DCPSPublication and DCPSSubscription (the endpoints' GUIDs, found
 * independently of what the node says). Usage: cyclone_graph NODE_NAME TIMEOUT_S. One line per sample on stdout:
 *   node PARTICIPANT_GID NAMESPACE NAME R READER_GID... W WRITER_GID...   (GIDs in hex)
 *   participant GUID USER_DATA        pub GUID PARTICIPANT_GUID TOPIC TYPE        sub GUID ... (the same)
 *   diag LEVEL NAME|HARDWARE_ID|KEY=VALUE|KEY=VALUE...
 *   log LEVEL NAME|FUNCTION|MSG
 * Exit 0 once NODE_NAME was announced with endpoints and a DiagnosticArray and a Log came, 1 at the timeout. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dds/dds.h"
#include "ros_graph.h"

static void hex(const unsigned char *v, size_t n) {
  for (size_t i = 0; i < n; i++) printf("%02x", v[i]);
}

static int take_node(dds_entity_t rd, const char *name) {
  void *samples[1] = {NULL};
  dds_sample_info_t info[1];
  int found = 0, n = dds_take(rd, samples, info, 1, 1);
  if (n > 0 && info[0].valid_data) {
    const rmw_dds_common_msg_dds__ParticipantEntitiesInfo_ *m = samples[0];
    for (uint32_t i = 0; i < m->node_entities_info_seq._length; i++) {
      const rmw_dds_common_msg_dds__NodeEntitiesInfo_ *node = &m->node_entities_info_seq._buffer[i];
      printf("node ");
      hex(m->gid.data, 24);
      printf(" %s %s R", node->node_namespace, node->node_name);
      for (uint32_t j = 0; j < node->reader_gid_seq._length; j++) printf(" "), hex(node->reader_gid_seq._buffer[j].data, 24);
      printf(" W");
      for (uint32_t j = 0; j < node->writer_gid_seq._length; j++) printf(" "), hex(node->writer_gid_seq._buffer[j].data, 24);
      printf("\n");
      found |= strcmp(node->node_name, name) == 0 && node->writer_gid_seq._length > 0 && node->reader_gid_seq._length > 0;
    }
  }
  if (n > 0) dds_return_loan(rd, samples, n);
  return found;
}

static int take_diag(dds_entity_t rd) {
  void *samples[1] = {NULL};
  dds_sample_info_t info[1];
  int found = 0, n = dds_take(rd, samples, info, 1, 1);
  if (n > 0 && info[0].valid_data) {
    const diagnostic_msgs_msg_dds__DiagnosticArray_ *m = samples[0];
    for (uint32_t i = 0; i < m->status._length; i++) {
      const diagnostic_msgs_msg_dds__DiagnosticStatus_ *s = &m->status._buffer[i];
      printf("diag %u %s|%s", s->level, s->name, s->hardware_id);
      for (uint32_t j = 0; j < s->values._length; j++) printf("|%s=%s", s->values._buffer[j].key, s->values._buffer[j].value);
      printf("\n");
      found = 1;
    }
  }
  if (n > 0) dds_return_loan(rd, samples, n);
  return found;
}

static int take_log(dds_entity_t rd) {
  void *samples[1] = {NULL};
  dds_sample_info_t info[1];
  int found = 0, n = dds_take(rd, samples, info, 1, 1);
  if (n > 0 && info[0].valid_data) {
    const rcl_interfaces_msg_dds__Log_ *m = samples[0];
    printf("log %u %s|%s|%s\n", m->level, m->name, m->function, m->msg);
    found = 1;
  }
  if (n > 0) dds_return_loan(rd, samples, n);
  return found;
}

static void take_builtin(dds_entity_t rd, const char *kind) {
  void *samples[1] = {NULL};
  dds_sample_info_t info[1];
  int n = dds_take(rd, samples, info, 1, 1);
  if (n > 0 && info[0].valid_data) {
    if (strcmp(kind, "participant") == 0) {
      const dds_builtintopic_participant_t *p = samples[0];
      void *data = NULL;
      size_t size = 0;
      printf("participant ");
      hex(p->key.v, 16);
      if (dds_qget_userdata(p->qos, &data, &size) && data != NULL) printf(" %.*s", (int)size, (const char *)data);
      printf("\n");
      dds_free(data);
    } else {
      const dds_builtintopic_endpoint_t *e = samples[0];
      printf("%s ", kind);
      hex(e->key.v, 16);
      printf(" ");
      hex(e->participant_key.v, 16);
      printf(" %s %s\n", e->topic_name, e->type_name);
    }
  }
  if (n > 0) dds_return_loan(rd, samples, n);
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s NODE_NAME TIMEOUT_S\n", argv[0]);
    return 2;
  }
  dds_time_t end = dds_time() + (dds_duration_t)(atof(argv[2]) * 1e9);
  dds_entity_t pp = dds_create_participant(DDS_DOMAIN_DEFAULT, NULL, NULL);
  dds_qos_t *qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(qos, DDS_DURABILITY_TRANSIENT_LOCAL);
  dds_qset_history(qos, DDS_HISTORY_KEEP_ALL, 0);
  dds_entity_t info_tp = dds_create_topic(pp, &rmw_dds_common_msg_dds__ParticipantEntitiesInfo__desc, "ros_discovery_info", NULL, NULL);
  dds_entity_t info_rd = dds_create_reader(pp, info_tp, qos, NULL);
  dds_entity_t log_tp = dds_create_topic(pp, &rcl_interfaces_msg_dds__Log__desc, "rt/rosout", NULL, NULL);
  dds_entity_t log_rd = dds_create_reader(pp, log_tp, qos, NULL);
  dds_qset_durability(qos, DDS_DURABILITY_VOLATILE);
  dds_entity_t diag_tp = dds_create_topic(pp, &diagnostic_msgs_msg_dds__DiagnosticArray__desc, "rt/diagnostics", NULL, NULL);
  dds_entity_t diag_rd = dds_create_reader(pp, diag_tp, qos, NULL);
  dds_delete_qos(qos);
  dds_entity_t parts = dds_create_reader(pp, DDS_BUILTIN_TOPIC_DCPSPARTICIPANT, NULL, NULL);
  dds_entity_t pubs = dds_create_reader(pp, DDS_BUILTIN_TOPIC_DCPSPUBLICATION, NULL, NULL);
  dds_entity_t subs = dds_create_reader(pp, DDS_BUILTIN_TOPIC_DCPSSUBSCRIPTION, NULL, NULL);
  if (pp < 0 || info_rd < 0 || diag_rd < 0 || log_rd < 0 || parts < 0 || pubs < 0 || subs < 0) {
    fprintf(stderr, "cyclone_graph: cannot create the participant or a reader\n");
    return 2;
  }
  int node = 0, diag = 0, logged = 0;
  while (!(node && diag && logged) && dds_time() < end) {
    node |= take_node(info_rd, argv[1]);
    diag |= take_diag(diag_rd);
    logged |= take_log(log_rd);
    take_builtin(parts, "participant");
    take_builtin(pubs, "pub");
    take_builtin(subs, "sub");
    fflush(stdout);
    dds_sleepfor(DDS_MSECS(10));
  }
  for (int i = 0; i < 200; i++) { /* the endpoints discovered meanwhile */
    take_builtin(pubs, "pub");
    take_builtin(subs, "sub");
    take_builtin(parts, "participant");
  }
  fflush(stdout);
  dds_delete(pp);
  return node && diag && logged ? 0 : 1;
}
