import type { ServerResponse } from 'node:http';

/**
 * The made certificate's CA, offered to tablets over HTTPS only (the redirect port serves nothing
 * but redirects): the page with its SHA-256 fingerprint (`/shopdeck-ca`) and the file.
 */

/** Where a tablet downloads the self-signed certificate's CA to trust it (over HTTPS only). */
export const CA_PATH = '/shopdeck-ca.crt';
/** The page that offers that download, with the CA's SHA-256 fingerprint to compare (HTTPS only). */
export const CA_PAGE_PATH = '/shopdeck-ca';

const escapeHtml = (t: string): string => t.replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);

/**
 * The CA download page: the fingerprint the tablet must show for the downloaded certificate (the
 * same one the server printed at start), the link, and where to switch it on. No script: it is
 * served under the console's page CSP like every page.
 */
export function caPageHtml(caFingerprint: string): string {
  const fp = escapeHtml(caFingerprint);
  return `<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>Shopdeck: trust this console on a tablet</title>
<style>body{font:16px/1.5 system-ui,sans-serif;max-width:40rem;margin:2rem auto;padding:0 1rem}code{font-size:1.05rem;word-break:break-all;background:#eef1f5;padding:.2rem .3rem}a.button{display:inline-block;padding:.6rem 1rem;border:1px solid #246;border-radius:.3rem;text-decoration:none}</style>
</head><body>
<h1>Trust this console on a tablet</h1>
<p>The console's HTTPS certificate is signed by its own small certificate authority. Install that
authority on the tablet once; after that, the tablet opens the console without a warning.</p>
<p><strong>SHA-256 fingerprint of the authority:</strong><br><code id="ca-fingerprint">${fp}</code></p>
<p>Before you trust it, compare this fingerprint with the one the server printed when it started
(<em>CA SHA-256 …</em>) and with the one the tablet shows for the downloaded certificate. If they
differ, do not install it: someone is between the tablet and the console.</p>
<p><a class="button" href="${CA_PATH}" download="shopdeck-ca.crt">Download the certificate authority</a></p>
<h2>Then</h2>
<ul>
<li><strong>Android</strong>: Settings → Security → Encryption &amp; credentials → Install a certificate → CA certificate.</li>
<li><strong>iPad</strong>: Settings → General → VPN &amp; Device Management → install the downloaded profile, then
Settings → General → About → Certificate Trust Settings → switch it on.</li>
</ul>
<p><a href="/">Back to the console</a></p>
</body></html>
`;
}

/** What the server knows of its made CA (none with a certificate of the owner's own). */
export interface CaInfo {
  pem: string;
  fingerprint: string;
}

/** `GET|HEAD /shopdeck-ca.crt`: the CA file; `notFound` when there is no made CA. */
export function serveCa(
  res: ServerResponse,
  method: string,
  ca: CaInfo | null | undefined,
  notFound: (res: ServerResponse) => void,
): void {
  if (!ca) return notFound(res);
  res.writeHead(200, {
    'Content-Type': 'application/x-x509-ca-cert',
    'Content-Disposition': 'attachment; filename="shopdeck-ca.crt"',
    'Content-Length': Buffer.byteLength(ca.pem),
    'Cache-Control': 'no-cache',
  });
  res.end(method === 'HEAD' ? undefined : ca.pem);
}

/** `GET|HEAD /shopdeck-ca`: the page; `notFound` when there is no made CA. */
export function serveCaPage(
  res: ServerResponse,
  method: string,
  ca: CaInfo | null | undefined,
  notFound: (res: ServerResponse) => void,
): void {
  if (!ca) return notFound(res);
  const html = caPageHtml(ca.fingerprint);
  res.writeHead(200, {
    'Content-Type': 'text/html; charset=utf-8',
    'Content-Length': Buffer.byteLength(html),
    'Cache-Control': 'no-store',
  });
  res.end(method === 'HEAD' ? undefined : html);
}
