/**
 * The console's one locale policy. Every date, time, number and relative age on screen is
 * written through the `Intl` formatters made here, so they all agree:
 *
 * - locale: a setting (`setLocalePolicy({ locale })`) when there is one, else the browser's
 *   languages in order (`navigator.languages`), the first one `Intl` supports; `en-US` last.
 * - time zone: a setting (`setLocalePolicy({ timeZone })`) when there is one, else the
 *   browser's own. Never UTC by accident: dates are never cut out of `toISOString()`.
 *
 * Formatters are cached per locale, time zone and options (building one is the costly part).
 * Machine-readable text (wire formats, file names, exported logs) does not come through here.
 */

export interface LocalePolicy {
  /** A BCP 47 tag (`de-DE`, `en-GB`); unset: the browser's languages. */
  locale?: string;
  /** An IANA time zone (`Europe/Berlin`); unset: the browser's. */
  timeZone?: string;
}

const FALLBACK_LOCALE = 'en-US';

let policy: LocalePolicy = {};
const formatters = new Map<string, Intl.NumberFormat | Intl.DateTimeFormat | Intl.RelativeTimeFormat>();
const supported = new Map<string, string>();

function validTimeZone(timeZone: string | undefined): string | undefined {
  if (!timeZone) return undefined;
  try {
    return new Intl.DateTimeFormat('en', { timeZone }).resolvedOptions().timeZone;
  } catch {
    return undefined;
  }
}

/** Replaces the settings of the policy (`{}`: follow the browser). An unknown time zone is ignored. */
export function setLocalePolicy(next: LocalePolicy): void {
  const timeZone = validTimeZone(next.timeZone);
  policy = { ...(next.locale ? { locale: next.locale } : {}), ...(timeZone ? { timeZone } : {}) };
  formatters.clear();
}

function browserLanguages(): readonly string[] {
  const nav = (globalThis as { navigator?: { languages?: readonly string[]; language?: string } }).navigator;
  if (nav?.languages && nav.languages.length > 0) return nav.languages;
  return nav?.language ? [nav.language] : [];
}

/** The first candidate `Intl` supports; a malformed tag is skipped, never thrown. */
function firstSupported(candidates: readonly string[]): string {
  const key = candidates.join('\n');
  let found = supported.get(key);
  if (found === undefined) {
    found = FALLBACK_LOCALE;
    for (const c of candidates) {
      try {
        const [s] = Intl.DateTimeFormat.supportedLocalesOf(c);
        if (s) {
          found = s;
          break;
        }
      } catch {
        // not a BCP 47 tag: try the next one
      }
    }
    supported.set(key, found);
  }
  return found;
}

/** The locale everything is written in now. */
export function currentLocale(): string {
  const langs = browserLanguages();
  return firstSupported(policy.locale ? [policy.locale, ...langs] : langs);
}

/** The time zone set, or undefined for the browser's own. */
export function currentTimeZone(): string | undefined {
  return policy.timeZone;
}

function cached<T extends Intl.NumberFormat | Intl.DateTimeFormat | Intl.RelativeTimeFormat>(
  kind: string,
  options: object,
  make: (locale: string) => T,
): T {
  const locale = currentLocale();
  const key = `${kind}|${locale}|${policy.timeZone ?? ''}|${JSON.stringify(options)}`;
  let f = formatters.get(key) as T | undefined;
  if (!f) {
    f = make(locale);
    formatters.set(key, f);
  }
  return f;
}

export function numberFormat(options: Intl.NumberFormatOptions = {}): Intl.NumberFormat {
  return cached('n', options, (locale) => new Intl.NumberFormat(locale, options));
}

/** Dates and times, in the policy's time zone. */
export function dateTimeFormat(options: Intl.DateTimeFormatOptions): Intl.DateTimeFormat {
  return cached(
    'd',
    options,
    (locale) =>
      new Intl.DateTimeFormat(locale, policy.timeZone ? { ...options, timeZone: policy.timeZone } : options),
  );
}

export function relativeTimeFormat(options: Intl.RelativeTimeFormatOptions = {}): Intl.RelativeTimeFormat {
  return cached('r', options, (locale) => new Intl.RelativeTimeFormat(locale, options));
}
