// How long the host held Chromium off its CPUs, so that the driver's
// timeouts count the time the page could run (python/servoamp/hoststall.py
// is the same measure for QEMU's console). The kernel counts, per thread,
// the time it was runnable but waiting for a CPU: the second field of
// /proc/PID/task/TID/schedstat. Held time from a mark is the longest such
// wait of any thread of this process and its descendants (Chromium's
// browser, GPU and renderer processes).

import fs from "node:fs";

// a wait of N ms ends after at most CAP * N ms on the host's clock
export const CAP = 8;

function children() {
  const kids = new Map();
  for (const d of fs.readdirSync("/proc")) {
    if (!/^\d+$/.test(d)) continue;
    let stat;
    try {
      stat = fs.readFileSync(`/proc/${d}/stat`, "utf8");
    } catch {
      continue;
    }
    const ppid = Number(stat.slice(stat.lastIndexOf(")") + 2).split(" ")[1]);
    if (!kids.has(ppid)) kids.set(ppid, []);
    kids.get(ppid).push(Number(d));
  }
  return kids;
}

/** Run-queue wait (ns) of every thread of this process tree: Map "pid/tid" -> ns. */
export function stallMark() {
  const kids = children();
  const out = new Map();
  const todo = [process.pid];
  while (todo.length) {
    const pid = todo.pop();
    todo.push(...(kids.get(pid) ?? []));
    let tids;
    try {
      tids = fs.readdirSync(`/proc/${pid}/task`);
    } catch {
      continue;
    }
    for (const tid of tids) {
      try {
        const f = fs.readFileSync(`/proc/${pid}/task/${tid}/schedstat`, "utf8").split(" ");
        out.set(`${pid}/${tid}`, Number(f[1]));
      } catch {
        /* gone, or no schedstat: counts as never held */
      }
    }
  }
  return out;
}

/** Milliseconds the most delayed thread was held off since mark. */
export function heldMs(mark) {
  let max = 0;
  for (const [k, ns] of stallMark()) max = Math.max(max, ns - (mark.get(k) ?? 0));
  return max / 1e6;
}

/** A clock of the time the page could run (python/servoamp/hoststall.py's
 * Deadline): wall and held time since it was made, in ms. */
export function runClock() {
  const start = Date.now();
  const mark = stallMark();
  return {
    wall: () => Date.now() - start,
    held: () => heldMs(mark),
    /** ms on the host's clock before budgetMs of running time, or
     * CAP * budgetMs in all, are spent; 0 once they are (the hold-offs are
     * read only once budgetMs have passed on the host's clock) */
    left(budgetMs) {
      const wall = this.wall();
      if (wall < budgetMs) return budgetMs - wall;
      if (wall >= CAP * budgetMs) return 0;
      return Math.max(0, Math.min(budgetMs - (wall - this.held()), CAP * budgetMs - wall));
    },
    spent(budgetMs) {
      return this.left(budgetMs) <= 0;
    },
    describe() {
      return `${(this.wall() / 1000).toFixed(1)} s in all, ${(this.held() / 1000).toFixed(1)} s of it with Chromium held off its CPUs`;
    },
  };
}
