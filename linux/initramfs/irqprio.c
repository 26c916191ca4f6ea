// SPDX-License-Identifier: MIT
/*
 * irqprio - give the interrupt thread of a named interrupt a SCHED_FIFO
 * priority (the board's /init runs it; busybox has no chrt).
 *
 *   irqprio NAME PRIO
 *
 * NAME is the action name of /proc/interrupts (for the cycle interrupt:
 * "cycle-interrupt", the UIO device's name). On a PREEMPT_RT kernel every
 * handler runs in a kernel thread "irq/NN-NAME" (SCHED_FIFO 50); this finds
 * the thread of interrupt NN and sets its priority. A kernel without
 * interrupt threads (the default kernel) has nothing to set: exit 0 with a
 * note. Exit 1 when the interrupt is not there or the priority cannot be
 * set.
 */
#include <ctype.h>
#include <dirent.h>
#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The Linux number of the interrupt whose action is @name, or -1. */
static int irq_of(const char *name)
{
	char line[512];
	FILE *f = fopen("/proc/interrupts", "r");
	int irq = -1;

	if (!f) {
		perror("irqprio: /proc/interrupts");
		return -1;
	}
	while (irq < 0 && fgets(line, sizeof(line), f)) {
		char *end, *tok, *last = NULL;
		long n = strtol(line, &end, 10);

		if (end == line || *end != ':')
			continue;
		/* the action name is the last field of the line */
		for (tok = strtok(end + 1, " \t\n"); tok; tok = strtok(NULL, " \t\n"))
			last = tok;
		if (last && !strcmp(last, name))
			irq = (int)n;
	}
	fclose(f);
	return irq;
}

/* The pid of the thread "irq/@irq-..." (comm is cut at 15 chars), or 0. */
static long irq_thread(int irq)
{
	char prefix[32], path[300], comm[32];
	struct dirent *de;
	long pid = 0;
	DIR *d = opendir("/proc");

	if (!d) {
		perror("irqprio: /proc");
		return 0;
	}
	snprintf(prefix, sizeof(prefix), "irq/%d-", irq);
	while (!pid && (de = readdir(d))) {
		FILE *f;

		if (!isdigit((unsigned char)de->d_name[0]))
			continue;
		snprintf(path, sizeof(path), "/proc/%s/comm", de->d_name);
		f = fopen(path, "r");
		if (!f)
			continue;
		if (fgets(comm, sizeof(comm), f) &&
		    !strncmp(comm, prefix, strlen(prefix)))
			pid = strtol(de->d_name, NULL, 10);
		fclose(f);
	}
	closedir(d);
	return pid;
}

int main(int argc, char **argv)
{
	struct sched_param sp = { 0 };
	long pid;
	int irq;

	if (argc != 3) {
		fprintf(stderr, "usage: irqprio NAME PRIO\n");
		return 2;
	}
	sp.sched_priority = atoi(argv[2]);
	irq = irq_of(argv[1]);
	if (irq < 0) {
		fprintf(stderr, "irqprio: no interrupt named %s in /proc/interrupts\n", argv[1]);
		return 1;
	}
	pid = irq_thread(irq);
	if (!pid) {
		printf("irqprio: %s (irq %d) has no interrupt thread: its handler runs in hard interrupt context\n",
		       argv[1], irq);
		return 0;
	}
	if (sched_setscheduler((pid_t)pid, SCHED_FIFO, &sp)) {
		fprintf(stderr, "irqprio: irq/%d (pid %ld): SCHED_FIFO %d: %s\n",
			irq, pid, sp.sched_priority, strerror(errno));
		return 1;
	}
	printf("irqprio: %s: irq/%d-%s (pid %ld) SCHED_FIFO %d\n",
	       argv[1], irq, argv[1], pid, sp.sched_priority);
	return 0;
}
