import { G2Fail, isRecord, readBody } from './fail';
import type { SimJob } from './state';

/**
 * The job resources of the REST design as both g2core servers answer them: the simulator
 * (jobs.ts) and the gateway's serial bridge (src/controllers/g2core/server/). Node-safe.
 */

/**
 * The body of `POST /job`: JSON `{"name","gcode"}` or multipart with a `file` field (and an
 * optional `name`). Status 101 for a body of neither shape, 10 for a file over `maxBytes`.
 */
export async function readJobUpload(req: Request, maxBytes: number): Promise<{ name: string; text: string }> {
  const type = req.headers.get('content-type') ?? '';
  let name: string;
  let text: string;
  if (type.includes('multipart/form-data')) {
    const form = await req.formData();
    const file = form.get('file');
    if (!file || typeof file === 'string') throw new G2Fail(101, 'multipart needs a "file" field');
    name = String(form.get('name') ?? file.name ?? '');
    if (file.size > maxBytes) throw new G2Fail(10, `${file.size} bytes > ${maxBytes}`);
    text = await file.text();
  } else {
    const body = await readBody(req);
    if (!isRecord(body) || typeof body.gcode !== 'string')
      throw new G2Fail(101, 'expected {"name":…,"gcode":…}');
    name = typeof body.name === 'string' ? body.name : '';
    text = body.gcode;
    if (text.length > maxBytes) throw new G2Fail(10, `${text.length} bytes > ${maxBytes}`);
  }
  return { name, text };
}

/** `GET /job/{id}`: the job, its progress from its operation, and its place in the queue. */
export function jobView(
  job: SimJob,
  op: { done: number; error: unknown } | undefined,
  position: number | null,
): Record<string, unknown> {
  const v: Record<string, unknown> = {
    id: job.id,
    name: job.name,
    state: job.state,
    lines: job.lines.length,
    done: op ? op.done : job.state === 'done' ? job.lines.length : 0,
    started: job.started === null ? null : new Date(job.started).toISOString(),
    finished: job.finished === null ? null : new Date(job.finished).toISOString(),
    operation: job.operation,
    position,
  };
  if (op?.error) v.error = op.error;
  return v;
}

/** Keeps the ended jobs' history bounded: the `keep` last to end stay, the older ones go. */
export function pruneEndedJobs(
  jobs: Map<number, { id: number; state: string; finished: number | null }>,
  keep: number,
): void {
  const ended = [...jobs.values()].filter((j) => !['queued', 'running', 'paused'].includes(j.state));
  for (const j of ended.sort((a, b) => (a.finished ?? 0) - (b.finished ?? 0)).slice(0, -keep))
    jobs.delete(j.id);
}
