import { z } from 'zod/mini';

/**
 * A record of the alarm centre (gateway/alarms.ts keeps them; the page shows them): one alarm or
 * message of one machine, from when the controller raised it to when it cleared it, and who
 * acknowledged it when. The same schema checks the gateway's file and the page's answers.
 */
export const alarmRecordSchema = z.object({
  id: z.string().check(z.maxLength(40)),
  machine: z.string().check(z.maxLength(100)),
  machineName: z.string().check(z.maxLength(200)),
  family: z.string().check(z.maxLength(40)),
  /** The condition (the family's alarm id, `xtool-flame`); one open record per machine and key. */
  key: z.string().check(z.maxLength(200)),
  severity: z.enum(['critical', 'warning', 'info']),
  text: z.string().check(z.maxLength(500)),
  /** Blocks every page until a person acknowledges it (an xTool flame). */
  blocking: z._default(z.boolean(), false),
  /** ms since epoch */
  since: z.number(),
  clearedAt: z.nullable(z.number()),
  ackBy: z.nullable(z.string().check(z.maxLength(200))),
  ackAt: z.nullable(z.number()),
});

export type AlarmRecord = z.infer<typeof alarmRecordSchema>;
